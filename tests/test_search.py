"""Schedule search (selpres.presentation.search, the Optuna sweeper plugin): schedules from a few numbers, worked out by
hand; a real Optuna study in SQLite that resumes (needs hydra-optuna-sweeper, else skipped)."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from selpres.errors import ConfigError
from selpres.presentation import search
from selpres.presentation.schedule import build_schedule
from selpres.presentation.search import schedule_overrides, shaped_schedule, shaped_sizes
from selpres.run.specs import task_specs

from conftest import compose, run_python


def test_a_schedule_worked_out_by_hand():
    """p = 2, first 0.1, growth 1, n = 1000: fractions 0.1, 0.55, 1 -> sizes 100, 550, 1000. Tilt 0, budget
    60,000: 20,000 presentations a stage, N = 200, round(36.4) = 36 (19,800), then round(20,200 / 1000) =
    20 on U: 59,800 in all."""
    s = shaped_schedule(2, 0.1, 1.0, 0.0, 1000, 60_000, "stratified", 1 / 3)
    assert s == {"sizes": [100, 550, 1000], "epochs": [200, 36, 20], "budget": None}


def test_a_loss_order_pays_for_its_choices_out_of_the_budget():
    """As above with loss_high: the two enlargements score 900 and 450 candidates, charged 300 + 150, so
    59,550 presentations are left to train: 19,850 a stage, N = round(198.5) = 198 (Python rounds half to
    even), round(36.09) = 36, and round((59,550 - 19,800 - 19,800) / 1000) = round(19.95) = 20."""
    s = shaped_schedule(2, 0.1, 1.0, 0.0, 1000, 60_000, "loss_high", 1 / 3)
    assert s == {"sizes": [100, 550, 1000], "epochs": [198, 36, 20], "budget": None}


def test_tilt_and_growth_move_the_presentations_and_the_sizes():
    """growth 2 (slow start): 0.1 + 0.9 * (1/2)^2 = 0.325 -> 325. tilt 2 ln 2 at p = 2: shares 1 : 2 : 4 of
    60,000, so 8,571.4 / 100 -> 86 epochs, 17,142.9 / 325 = 52.7 -> 53 (17,225), and (60,000 - 8,600 -
    17,225) / 1000 = 34.2 -> 34."""
    s = shaped_schedule(2, 0.1, 2.0, 2 * math.log(2), 1000, 60_000, "random", 0.0)
    assert s == {"sizes": [100, 325, 1000], "epochs": [86, 53, 34], "budget": None}


def test_p_zero_is_conventional_cut_to_the_budget():
    assert shaped_schedule(0, 0.3, 1.0, 0.5, 1002, 70_560, "loss_high", 1 / 3) == {
        "sizes": [1002],
        "epochs": None,
        "budget": 70_560,
    }
    raw = {"search_p": "0", "search_first": "0.3", "search_growth": "1", "search_tilt": "0", "search_budget": "70560"}
    assert schedule_overrides(raw, 1002, "random", 0.0) == [
        "schedule.sizes=[1002]",
        "schedule.epochs=null",
        "schedule.budget=70560",
    ]


def test_sizes_merged_by_rounding_reach_the_job_which_refuses_them():
    """0.99 of 100 growing by quarters: 99, 99.25, 99.5, 99.75, 100 round to 99, 99, 100, 100, 100; the
    job's schedule check names schedule.sizes (in a search, that trial fails alone)."""
    sizes = shaped_sizes(4, 0.99, 1.0, 100)
    assert sizes == [99, 99, 100, 100, 100]
    with pytest.raises(ConfigError, match=r"schedule\.sizes.*strictly increasing"):
        build_schedule(sizes, [1] * 5, 100)
    with pytest.raises(ConfigError, match="search"):
        shaped_sizes(-1, 0.1, 1.0, 100)


HAND = {
    "search_p": "2",
    "search_first": "0.1",
    "search_growth": "1",
    "search_tilt": "0",
    "search_budget": "60000",
}  # the schedule of test_a_loss_order_pays_for_its_choices_out_of_the_budget


def test_total_cost_and_the_partner_of_the_confirmation_worked_by_hand():
    """loss_high 100, 550, 1000 x 198, 36, 20 epochs: 19,800 + 19,800 + 20,000 = 59,600 trained, plus
    300 + 150 charged = 60,050 in all; stratified pays nothing for choosing (59,600)."""
    s = shaped_schedule(2, 0.1, 1.0, 0.0, 1000, 60_000, "loss_high", 1 / 3)
    assert search.total_cost(s, 1000, "loss_high", 1 / 3) == 60_050
    assert search.total_cost(s, 1000, "stratified", 1 / 3) == 59_600
    commands = search.confirmation_commands([(HAND, "loss_high")], 1000, 1 / 3)
    staged, partner, paper, paper_partner, target, report = commands
    run = "python train.py -m name=search-confirm seed=0 replicas=30 eval.every=1"
    assert staged == (
        f"{run} schedule.name=search schedule.order=loss_high 'schedule.sizes=[100,550,1000]' "
        "'schedule.epochs=[198,36,20]' 'schedule.budget=null'"
    )
    assert partner == f"{run} schedule=matched schedule.budget=60050"
    assert paper == f"{run} schedule=selective"  # the paper's schedule and its partner, the reference
    assert paper_partner == f"{run} schedule=matched schedule.budget=70560"
    assert target == f"{run} schedule=conventional"
    assert report == "python -m selpres.report outputs/sweeps/search-confirm"
    # p = 0 is conventional training cut to the budget: its own compute-matched partner
    cut = search.confirmation_commands([({**HAND, "search_p": "0"}, "random")], 1000, 1 / 3)
    assert "'schedule.budget=60000'" in cut[0] and cut[1:] == commands[2:]
    # several schedules: loss_low's is loss_high's, so is its partner (run once); random pays no charge, so
    # its epochs are those of test_a_schedule_worked_out_by_hand (200, 36, 20: 59,800 presentations)
    best = [(HAND, "loss_high"), (HAND, "loss_low"), (HAND, "random")]
    three = search.confirmation_commands(best, 1000, 1 / 3)
    assert three[:3] == [staged, partner, staged.replace("loss_high", "loss_low")]
    assert "schedule.order=random" in three[3] and "'schedule.epochs=[200,36,20]'" in three[3]
    assert three[4] == f"{run} schedule=matched schedule.budget=59800" and three[5:] == commands[2:]


def test_the_search_is_scored_on_a_validation_draw_and_confirmed_on_other_seeds():
    """The search's objective set (data.test_seed 7919) is not the held-out test set (the default seed),
    and the search seeds are not the confirmation seeds."""
    cfg, default = compose("experiment=search"), compose()
    assert cfg.data.test_seed != default.data.test_seed
    searched = set(range(cfg.seed, cfg.seed + cfg.replicas))
    assert len(searched) >= 5 and not searched & set(range(30))  # confirmation: seed=0 replicas=30


def test_the_validation_set_shares_no_pattern_with_the_held_out_set_and_seeds_nothing_else(tmp_path):
    """Two jobs differing only in data.test_seed (the search's 7919 against the default) train identically
    (exemplar set, scaler, every curve's training MSE and the final weights agree exactly), and their
    held-out sets are two draws of 10,000 patterns with no pattern in common."""
    import torch

    from selpres.data.task import load_task
    from selpres.run.train import train

    base = [
        "replicas=2",
        "schedule.sizes=[50,1002]",
        "schedule.epochs=[3,2]",
        "schedule.order=loss_high",
        "logging.progress=false",
        "logging.tensorboard=false",
    ]
    val, test = compose(*base, "data.test_seed=7919"), compose(*base)
    tv, tt = load_task(*task_specs(val)), load_task(*task_specs(test))
    assert torch.equal(tv.exemplar.X, tt.exemplar.X) and torch.equal(tv.exemplar.Y, tt.exemplar.Y)
    assert all(torch.equal(getattr(tv.scaler, k), getattr(tt.scaler, k)) for k in ("x_min", "x_max", "y_min", "y_max"))
    hv, ht = tv.tests.heldout.X, tt.tests.heldout.X
    assert hv.shape == ht.shape == (10_000, 6)
    shared = {tuple(r) for r in hv.tolist()} & {tuple(r) for r in ht.tolist()}
    assert not shared
    (tmp_path / "val").mkdir(), (tmp_path / "test").mkdir()
    rv, rt = train(val, tmp_path / "val"), train(test, tmp_path / "test")
    assert [c["train_mse"] for c in rv["curves"]] == [c["train_mse"] for c in rt["curves"]]
    wv, wt = torch.load(tmp_path / "val" / "weights.pt"), torch.load(tmp_path / "test" / "weights.pt")
    assert all(torch.equal(a, b) for a, b in zip(wv["params"], wt["params"]))
    assert rv["summary"]["heldout_rms_nm_overall"] != rt["summary"]["heldout_rms_nm_overall"]


@settings(max_examples=200, deadline=None)
@given(
    p=st.integers(1, 4),
    first=st.floats(0.02, 0.5),
    growth=st.floats(0.3, 3.0),
    tilt=st.floats(-1.0, 2.0),
    order=st.sampled_from(["stratified", "loss_high", "reselect"]),
)
def test_every_searched_schedule_builds_and_spends_the_budget(p, first, growth, tilt, order):
    """Any point of the search space is a valid schedule (selpres.presentation.schedule accepts it) whose training and
    selection presentations sum to the budget within n / 2, unless one epoch a stage already exceeds it."""
    n, budget = 1002, 70_560
    s = shaped_schedule(p, first, growth, tilt, n, budget, order, 1 / 3)
    sch = build_schedule(s["sizes"], s["epochs"], n, s["budget"])  # sizes never merge at n = 1002 here
    charge = sum(math.ceil(round((n - k) / 3, 9)) for k in s["sizes"][:-1]) if order == "loss_high" else 0
    if sum(s["sizes"]) + charge <= budget - n:
        assert abs(sch.presentations + charge - budget) <= n / 2
    assert sch.sizes[-1] == n and len(sch.sizes) == p + 1


@pytest.mark.slow
def test_optuna_study_in_sqlite_runs_trials_as_jobs_and_resumes(tmp_path):
    """Two trials, then the same command with n_trials = 3 runs one more (the study's total), each trial an
    ordinary job folder with results.json."""
    pytest.importorskip("hydra_plugins.hydra_optuna_sweeper", reason="needs hydra-optuna-sweeper==1.3.0")
    optuna = pytest.importorskip("optuna")
    db = tmp_path / "study.db"
    args = [
        "train.py",
        "experiment=search",
        "replicas=2",
        "logging.progress=false",
        "hydra.sweeper.params.search_budget=4000",
        f"hydra.sweeper.storage=sqlite:///{db}",
        f"hydra.sweep.dir={tmp_path / 'sweep'}",
        "data.heldout=300",
        "eval.heldout_curve=300",
    ]
    for trials in (2, 3):
        p = run_python(*args, f"hydra.sweeper.n_trials={trials}")
        assert p.returncode == 0, p.stderr[-3000:]
    study = optuna.load_study(study_name="schedule-search", storage=f"sqlite:///{db}")
    assert len(study.trials) == 3 and all(t.state.name == "COMPLETE" for t in study.trials)
    assert "finished trials; running 1 more" in p.stdout + p.stderr
    jobs = list((tmp_path / "sweep").glob("*/results.json"))
    assert 1 <= len(jobs) <= 3 and (tmp_path / "sweep" / "optimization_results.yaml").exists()
    # the confirmation: the best schedule's job, run as confirm.sh says, spends what its partner is given
    lines = (tmp_path / "sweep" / "confirm.sh").read_text().splitlines()
    at = next(i for i, x in enumerate(lines) if "schedule.name=search" in x)  # the best trial's schedule
    staged, after = lines[at], lines[at + 1]
    best = study.best_trial
    assert f"schedule.order={best.params['schedule.order']}" in staged
    small = [
        "replicas=2",
        "data.heldout=300",
        "eval.heldout_curve=300",
        "logging.progress=false",
        f"hydra.sweep.dir={tmp_path / 'confirm'}",
    ]
    overrides = [o.strip("'") for o in staged.split()[2:]]  # after "python train.py", from "-m" on
    p = run_python("train.py", *overrides, *small)
    assert p.returncode == 0, p.stderr[-3000:]
    (res,) = [json.loads(f.read_text()) for f in (tmp_path / "confirm").glob("*/results.json")]
    assert res["seeds"] == [0, 1] and res["config"]["data"]["test_seed"] == 0
    if len(res["schedule"]["sizes"]) > 1:  # its partner follows it, at what the job spent in all
        assert after.endswith(f"schedule=matched schedule.budget={res['presentations_done']}")
    else:  # p = 0: conventional cut to the budget, its own partner
        assert "schedule=matched" not in after


def test_an_unreadable_optuna_storage_is_one_line_exit_2_and_left_as_it_is(tmp_path, capsys):
    """Issue 26's audit: a storage file that is not a database ended in sqlalchemy's 88-line traceback."""
    pytest.importorskip("optuna")
    from hydra_plugins.selpres_search._sweeper import _finished_trials

    bad = tmp_path / "search.db"
    bad.write_bytes(bytes(range(256)) * 20)
    with pytest.raises(SystemExit) as exit_:
        _finished_trials(f"sqlite:///{bad}", "schedule-search")
    assert exit_.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"error: hydra.sweeper.storage=sqlite:///{bad} cannot be read (DatabaseError") and (
        "move the file aside" in line
    )
    assert bad.read_bytes() == bytes(range(256)) * 20
    assert _finished_trials(f"sqlite:///{tmp_path / 'new.db'}", "schedule-search") == 0  # no study yet: none
