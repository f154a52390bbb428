"""The parametric schedule (configs/schedule/stages.yaml, selpres.presentation.proportions): every knob one key, the
presets its instances, every unbuildable schedule refused in one line naming the keys, and a sweep of its keys run
whole."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from selpres.errors import ConfigError
from selpres.presentation.proportions import check_form, rule_of, schedule_of, split_budget, stage_sizes
from selpres.presentation.schedule import build_schedule

from conftest import CONFIGS, REPO, cfg_of, compose, load_group

N = 1002


def stages(**keys):
    """The parametric schedule with stages.yaml's values and ``keys`` over them, as plain values."""
    node = {**dict(load_group("schedule", "stages")), "sizes": None, "epochs": None, "budget": None, **keys}
    return schedule_of(node, N)[0]


# ----------------------------------------------------------------------------------- the rule, derived by hand
def test_sizes_by_hand():
    # geometric from 50 to 1002, p = 3: 50 * 20.04 ** (1/3) = 135.8, 50 * 20.04 ** (2/3) = 368.96
    assert stage_sizes(3, 50, "geometric", N) == [50, 136, 369, 1002]
    # linear from 50: steps of (1002 - 50) / 4 = 238
    assert stage_sizes(4, 50, "linear", N) == [50, 288, 526, 764, 1002]
    # a share: 0.1 * 1002 = 100.2 -> 100; geometric p = 2: 0.1 ** 0.5 * 1002 = 316.86 -> 317
    assert stage_sizes(2, 0.1, "geometric", N) == [100, 317, 1002]
    # the paper's: n_2..n_4 = 100, 400, 800 of 1002 (scaled to n = 2004: doubled), n_1 as given
    assert stage_sizes(4, 10, "paper", N) == [10, 100, 400, 800, 1002]
    assert stage_sizes(4, 10, "paper", 2 * N) == [10, 200, 800, 1600, 2004]
    assert stage_sizes(0, None, None, N) == [N]


def test_epochs_and_budgets_by_hand():
    assert stages(p=4, growth="paper", profile="increasing").epochs == [10, 20, 30, 40, 50]  # 150 * k / 15
    assert stages(p=4, growth="paper", profile="decreasing").epochs == [50, 40, 30, 20, 10]
    assert stages(p=3).epochs == [37, 37, 38, 38]  # 150 / 4 = 37.5: the remainder to the later stages
    # a budget split exactly: the paper's 70,560 over its sizes (sum 2,352) is 30 epochs each, no partial epoch
    sel = stages(p=4, growth="paper", total_epochs=None, budget=70_560)
    assert sel.epochs == [30] * 5 and sel.presentations == 70_560 and sel.stages[-1].extra == 0
    # one stage: as many whole epochs as fit, the rest a partial epoch (the matched preset's 70 + 420)
    one = stages(p=0, total_epochs=None, budget=70_560)
    assert (one.stages[0].epochs, one.stages[0].extra) == (70, 420)


@pytest.mark.parametrize("profile", ["equal", "increasing", "decreasing"])
@pytest.mark.parametrize("p", [1, 2, 4, 8])
def test_a_budget_is_spent_exactly_and_shaped_by_the_profile(p, profile):
    s = stages(p=p, first=0.05, profile=profile, total_epochs=None, budget=70_560)
    assert s.presentations == 70_560  # every shape at the same cost
    per = [st.epochs for st in s.stages]
    # N_i follows its weight to within one epoch of the ideal share (the last stage also takes the leftover)
    w = {"equal": [1] * (p + 1), "increasing": list(range(1, p + 2)), "decreasing": list(range(p + 1, 0, -1))}[profile]
    ideal = [x * 70_560 / sum(a * b for a, b in zip(w, s.sizes)) for x in w]
    assert all(math.floor(x) <= e <= math.floor(x) + 1 for e, x in zip(per[:-1], ideal[:-1]))
    assert per[-1] >= math.floor(ideal[-1])  # the last stage also takes what is left, as whole and partial epochs


def test_the_sensitivity_designs_are_instances():
    """sel_p1..p6 (written by scripts/make_sensitivity_designs.py, round() of its own formula) are stages p = k."""
    for k in range(1, 7):
        d = load_group("design", f"sel_p{k}").schedule
        s = stages(p=k)
        assert (s.sizes, s.epochs) == (list(d.sizes), list(d.epochs)), k
    d = load_group("design", "sel_growth_linear").schedule
    assert stages(growth="linear").sizes == list(d.sizes)
    d = load_group("design", "sel_Ni_increasing").schedule
    assert stages(growth="paper", profile="increasing").epochs == list(d.epochs)


PRESETS = {  # preset -> its parametric equivalent (the comment in its file names the same)
    "selective": {"growth": "paper"},
    "random_growth": {"growth": "paper"},
    "geometric": {"first": 0.0625},
    "linear": {"first": 0.2, "growth": "linear"},
    "two_stage": {"p": 1, "first": 0.1},
    "conventional": {"p": 0},
    "matched": {"p": 0, "total_epochs": None, "budget": 70_560},
}


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_every_preset_is_an_instance(preset):
    c = load_group("schedule", preset)
    listed = build_schedule(list(c.sizes), None if c.epochs is None else list(c.epochs), N, c.get("budget"))
    assert stages(**PRESETS[preset]).stages == listed.stages
    assert f"schedule=stages {' '.join(f'schedule.{k}={v}' for k, v in PRESETS[preset].items())}".replace(
        "None", "null"
    ) in (CONFIGS / "schedule" / f"{preset}.yaml").read_text().replace("  #", "")


def test_listed_schedules_are_described_in_the_rules_words():
    sel = rule_of(build_schedule([50, 100, 400, 800, 1002], [30] * 5, N))
    assert sel == {"form": "listed", "growth": "paper", "profile": "equal"}
    assert rule_of(build_schedule([0.0625, 0.125, 0.25, 0.5, 1.0], [30] * 5, N))["growth"] == "geometric"
    assert rule_of(build_schedule([50, 100, 400, 800, 1002], [10, 20, 30, 40, 50], N))["profile"] == "increasing"
    assert rule_of(build_schedule([50, 60, 1002], [1, 5, 2], N)) == {
        "form": "listed",
        "growth": "listed",
        "profile": "listed",
    }


# ------------------------------------------------------------------------------------------------- refusals
REFUSED = [  # (overrides, the key named, words of what is allowed)
    (["schedule=stages", "schedule.p=-1"], "schedule.p", ">= 0"),
    (["schedule=stages", "schedule.first=2000"], "schedule.first", "below n = 1,002"),
    (["schedule=stages", "schedule.first=1.5"], "schedule.first", "share of n in (0, 1)"),
    (["schedule=stages", "schedule.total_epochs=null", "schedule.budget=20"], "schedule.budget", "one pass over A_1"),
    (["schedule=stages", "schedule.total_epochs=null", "schedule.budget=1000"], "schedule.budget", "at least 1,856"),
    (["schedule=stages", "schedule.budget=70560"], "schedule.budget", "schedule.total_epochs=null"),
    (["schedule=stages", "schedule.total_epochs=null"], "schedule.total_epochs", "one of schedule.total_epochs"),
    (["schedule=stages", "schedule.total_epochs=3"], "schedule.total_epochs", ">= 5"),
    (["schedule=stages", "schedule.growth=cubic"], "schedule.growth", "geometric, linear, paper"),
    (["schedule=stages", "schedule.profile=flat"], "schedule.profile", "equal, increasing, decreasing"),
    (["schedule=stages", "schedule.growth=paper", "schedule.p=2"], "schedule.p", "4 with schedule.growth=paper"),
    (["schedule=stages", "schedule.p=400", "schedule.first=1"], "schedule.p", "sizes that grow"),
    (
        ["schedule=stages", "schedule.epochs=[1,2,3,4,5]"],
        "schedule.epochs",
        "schedule.total_epochs=null; with epochs listed also schedule.profile=null",
    ),
    (["schedule=stages", "schedule.sizes=[0.5,1.0]"], "schedule.p", "null with listed sizes"),
    (["schedule=selective", "schedule.p=2"], "schedule.p", "schedule.sizes=[50,100,400,800,1002]"),
    (["schedule=selective", "schedule.growth=linear"], "schedule.growth", "read only with schedule.p set"),
    (["schedule=infobatch", "schedule.p=1"], "schedule.p", "null with listed sizes"),
]


@pytest.mark.parametrize("overrides,key,words", REFUSED, ids=[" ".join(r[0][1:]) for r in REFUSED])
def test_unbuildable_schedules_are_refused_naming_the_keys(overrides, key, words):
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as e:
        prepare(resolve(cfg_of(*overrides)))
    assert e.value.key == key and words in str(e.value), str(e.value)
    assert "\n" not in str(e.value)


def test_sizes_not_nested_are_refused_without_a_fraction_form_that_is_as_wrong():
    """Decreasing counts: their fractions decrease too, so no fraction form is suggested; counts that only miss n
    still get theirs."""
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as e:
        prepare(resolve(cfg_of("schedule.sizes=[100,50,1002]", "schedule.epochs=[1,1,1]")))
    assert "strictly increasing" in str(e.value) and "as fractions" not in str(e.value)
    with pytest.raises(ConfigError) as e:
        prepare(resolve(cfg_of("schedule.sizes=[100,200,500]", "schedule.epochs=[1,1,1]")))
    assert "schedule.sizes=[0.2,0.4,1.0]" in str(e.value)


def test_form_checks_need_no_data():
    with pytest.raises(ConfigError, match="schedule.p"):
        check_form({"p": -3})
    check_form({"p": 2, "growth": "linear", "first": 0.1, "profile": "equal", "total_epochs": 9})  # fine
    with pytest.raises(ConfigError, match="at least"):
        split_budget("equal", 100, [50, 100])


def test_a_refusal_is_one_line_and_exit_2(tmp_path):
    out = subprocess.run(
        [sys.executable, str(REPO / "train.py"), "schedule=stages", "schedule.p=-1", f"hydra.run.dir={tmp_path / 'x'}"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip() == "error: schedule.p=-1 is not allowed: expected a whole number >= 0"
    assert not (tmp_path / "x").exists()  # nothing of the refused run is left


# ------------------------------------------------------------------------------------------- identity, record
def test_the_parametric_keys_enter_a_listed_config_neither_record_nor_identity():
    from selpres.run.specs import recorded

    rec = recorded(compose("schedule=selective"))
    assert not {"p", "first", "growth", "profile", "total_epochs"} & set(rec["schedule"])
    rec = recorded(compose("schedule=stages", "schedule.p=2"))
    assert rec["schedule"]["p"] == 2 and rec["schedule"]["growth"] == "geometric"


@pytest.mark.slow
def test_the_documented_sweep_runs_every_combination(tmp_path):
    """-m schedule=stages schedule.p=1,2,4,8 schedule.first=0.05,0.1: 8 valid jobs, each recording what ran."""
    args = ["-m", "schedule=stages", "schedule.p=1,2,4,8", "schedule.first=0.05,0.1", "schedule.total_epochs=9"]
    args += ["data.heldout=300", "eval.heldout_curve=300", "logging.tensorboard=false", "replicas=1"]
    out = subprocess.run(
        [sys.executable, str(REPO / "train.py"), *args, f"hydra.sweep.dir={tmp_path}"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    found = {}
    for path in tmp_path.rglob("results.json"):
        r = json.loads(path.read_text())
        c = r["config"]["schedule"]
        found[(c["p"], c["first"])] = r
    assert sorted(found) == sorted((p, f) for p in (1, 2, 4, 8) for f in (0.05, 0.1))
    for (p, first), r in found.items():
        s = r["schedule"]
        assert s["p"] == p and len(s["sizes"]) == p + 1 and s["sizes"][0] == math.floor(first * N + 0.5)
        assert sum(s["epochs"]) == 9 and r["presentations_done"] == sum(a * b for a, b in zip(s["sizes"], s["epochs"]))
    assert out.stderr.count("jobs done") == 8 and "sweep: 8/8 jobs done" in out.stderr  # the sweep's progress


def test_an_appended_p_on_a_listed_schedule_is_refused(tmp_path):
    """+schedule.p=1 on schedule=selective (the issue's lie: p = 4 ran, p: 1 recorded) is refused, nothing kept."""
    out = subprocess.run(
        [
            sys.executable,
            str(REPO / "train.py"),
            "schedule=selective",
            "+schedule.p=1",
            f"hydra.run.dir={tmp_path / 'x'}",
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "schedule.p=1" in out.stderr
    assert not (tmp_path / "x").exists()
