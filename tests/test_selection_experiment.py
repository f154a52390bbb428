"""experiment=selection: the sweep composes, every point of configs/design/selection/ validates and costs
what its file says (training presentations + the charge for choosing, worked out by hand), every staged run
has a one-stage partner at exactly its total cost, and a tiny version runs end to end through the documented
command and the report (slow)."""

from __future__ import annotations

import functools
import json
import re

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import Glob
from omegaconf import OmegaConf

from selpres.presentation.orders import planned_charge
from selpres.run.problem import prepare
from selpres.run.resolve import resolve
from selpres.storage import flatten

from conftest import CONFIGS, cfg_of, compose, report_of, run_python

POINTS_DIR = CONFIGS / "design" / "selection"
EXPERIMENT = CONFIGS / "experiment" / "selection.yaml"
N = 1002
CONVENTIONAL = 150 * N  # 150,300: the paper's conventional cost, the budgets' reference
ORDERS = ("stratified", "random", "coverage", "loss_high", "loss_low", "reselect")
# by hand: the paper's stages 50 + 100 + 400 + 800 + 1002 = 2352 patterns, N_i = 16, 30, 48 epochs each
TRAINING = {"b25": 2352 * 16, "b47": 2352 * 30, "b75": 2352 * 48}  # 37,632, 70,560, 112,896
# the loss orders score U \ A_k at each of the four enlargements: 952, 902, 602, 202 candidates x 1/3,
# rounded up per enlargement: 317.3 -> 318, 300.7 -> 301, 200.7 -> 201, 67.3 -> 68
CHARGE = 318 + 301 + 201 + 68  # 888


def point_files() -> list[str]:
    return sorted(p.stem for p in POINTS_DIR.glob("*.yaml"))


def swept_points() -> list[str]:
    """The design points the experiment sweeps, as Hydra's override parser reads its list."""
    value = OmegaConf.load(EXPERIMENT).hydra.sweeper.params["design/selection"]
    override = OverridesParser.create().parse_overrides([f"design/selection={value}"])[0]
    if isinstance(override.value(), Glob):  # Hydra sweeps the group's options the glob matches
        return list(override.value().filter(point_files()))
    return list(override.sweep_string_iterator())


def stated_cost(point: str) -> int:
    """The cost a point's file states on its line "# cost: N presentations"."""
    text = (POINTS_DIR / f"{point}.yaml").read_text()
    (cost,) = re.findall(r"^# cost: ([\d,]+) presentations$", text, re.M)
    return int(cost.replace(",", ""))


@functools.cache
def composed(point: str):
    return cfg_of("experiment=selection", f"design/selection={point}")


def kind(point: str) -> str:
    """What a point runs: an order, matched, matched_charged, or conventional ("b25_loss_high" ->
    "loss_high")."""
    return point.split("_", 1)[-1]


POINTS = swept_points()


def test_the_experiment_is_a_two_at_a_time_multirun_of_thirty_paired_seeds_scored_every_epoch():
    cfg = compose("experiment=selection", hydra=True)
    assert (cfg.name, cfg.seed, cfg.replicas, cfg.threads, cfg.eval.every) == ("selection", 0, 30, 1, 1)
    assert cfg.hydra.mode.name == "MULTIRUN" and cfg.hydra.launcher.n_jobs == 2
    assert cfg.hydra.sweep.dir == "outputs/sweeps/selection"
    assert str(cfg.hydra.sweeper.params.topology).split(",") == ["6-4-2", "6-8-2", "6-13-2"]


def test_every_point_file_is_swept_once_and_the_job_count_is_the_documented_one():
    assert len(set(POINTS)) == len(POINTS), "a point listed twice"
    assert sorted(POINTS) == point_files(), f"unswept: {sorted(set(point_files()) - set(POINTS))}"
    (documented,) = re.findall(r"^# Jobs: .* = (\d+)\.$", EXPERIMENT.read_text(), re.M)
    assert len(POINTS) * 3 == int(documented) == 75
    staged = {p for p in POINTS if kind(p) in ORDERS}
    assert staged == {f"{b}_{o}" for b in TRAINING for o in ORDERS}  # every order at every budget


def test_the_loss_orders_charge_is_worked_by_hand():
    sizes = [50, 100, 400, 800, 1002]
    assert planned_charge("loss_high", sizes, 1 / 3) == planned_charge("loss_low", sizes, 1 / 3) == CHARGE
    assert all(planned_charge(o, sizes, 1 / 3) == 0 for o in ("stratified", "random", "coverage", "reselect"))


def expected_cost(point: str) -> int:
    """A point's cost worked out from its name alone: training by hand, plus 888 where a loss order (or its
    partner) pays for choosing; the paper's conventional run 150,300."""
    if point == "conventional":
        return CONVENTIONAL
    budget, what = point.split("_", 1)
    return TRAINING[budget] + (CHARGE if what in ("loss_high", "loss_low", "matched_charged") else 0)


@pytest.mark.parametrize("point", POINTS)
def test_each_point_validates_and_costs_what_its_file_says(point):
    cfg = composed(point)
    prob = prepare(resolve(cfg))  # the checks against the exemplar set, the orders, the stage-wise selection
    sch = prob.schedule
    order = cfg.schedule.order
    cost = sch.presentations + planned_charge(order, sch.sizes, cfg.schedule.selection_cost)
    assert cost == stated_cost(point) == expected_cost(point)
    assert (cfg.seed, cfg.replicas, prob.seeds) == (0, 30, list(range(30)))
    if len(sch.sizes) > 1:
        assert sch.sizes == [50, 100, 400, 800, 1002] and len(set(sch.epochs)) == 1
        assert order == kind(point)
        assert prob.selector.describe()["stagewise"] == (order in ("loss_high", "loss_low", "reselect"))
        assert prob.selector.planned_charge(sch) == planned_charge(order, sch.sizes, cfg.schedule.selection_cost)


def _outside_schedule(cfg) -> dict:
    """What a compute-matched partner must share: the config outside schedule.* (and the job's name)."""
    return {
        k: v for k, v in flatten(OmegaConf.to_container(cfg, resolve=True)).items() if not k.startswith("schedule.")
    }


def test_every_staged_run_has_a_one_stage_partner_at_exactly_its_total_cost_and_the_same_other_settings():
    one_stage = {stated_cost(p): p for p in POINTS if len(composed(p).schedule.sizes) == 1}
    assert len(one_stage) == 7  # two partners per budget and the paper's conventional run
    for p in POINTS:
        cfg = composed(p)
        if len(cfg.schedule.sizes) == 1:
            continue
        partner = one_stage.get(stated_cost(p))
        assert partner is not None, f"{p}: no one-stage run at its {stated_cost(p):,} presentations"
        assert kind(partner) == ("matched_charged" if kind(p).startswith("loss") else "matched")
        assert _outside_schedule(composed(partner)) == _outside_schedule(cfg)


def test_on_the_larger_task_every_staged_run_has_its_partner_closest_and_within_a_hundredth_of_a_percent():
    """experiment=selection data=sampled (n = 10,000): the points' counts apply as fractions of n and the
    partners' budgets scale by n/1002 (selpres.presentation.proportions), so totals match only to rounding. By hand for
    the loss orders at 25 %: stages 499, 998, 3992, 7984, 10000 x 16 = 375,568 trained + 3167 + 3001 +
    2003 + 672 = 8,843 charged = 384,411, against 38,520 x 10,000 / 1002 = 384,431 (20 more)."""
    from selpres.presentation.proportions import fit_schedule
    from selpres.presentation.schedule import build_schedule

    n, totals = 10_000, {}
    for point in POINTS:
        sch = composed(point).schedule
        sizes, budget, _ = fit_schedule(list(sch.sizes), sch.budget, n)
        built = build_schedule(sizes, None if sch.epochs is None else list(sch.epochs), n, budget)
        totals[point] = built.presentations + planned_charge(sch.order, built.sizes, sch.selection_cost)
    assert totals["b25_loss_high"] == 384_411 and totals["b25_matched_charged"] == 384_431
    one_stage = [p for p in POINTS if len(composed(p).schedule.sizes) == 1]
    for p in POINTS:
        if p in one_stage:
            continue
        closest = min(one_stage, key=lambda q: abs(totals[q] - totals[p]))
        assert kind(closest) == ("matched_charged" if kind(p).startswith("loss") else "matched")
        assert closest.split("_")[0] == p.split("_")[0] and abs(totals[closest] / totals[p] - 1) < 1e-4


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The documented command on four points at 25 % (stratified and loss_high with their partners), one
    topology, 2 seeds, a small held-out set; then the report."""
    out = tmp_path_factory.mktemp("selection")
    picked = ["b25_stratified", "b25_matched", "b25_loss_high", "b25_matched_charged"]
    run = run_python(
        "train.py",
        "experiment=selection",
        "design/selection=" + ",".join(picked),
        "topology=6-4-2",
        "replicas=2",
        "data.heldout=200",
        "eval.heldout_curve=200",
        "logging.progress=false",
        f"hydra.sweep.dir={out / 'sweep'}",
    )
    assert run.returncode == 0, run.stderr[-3000:]
    jobs = {
        re.search(r"design_selection=([^,]+)", p.parent.name).group(1): json.loads(p.read_text())
        for p in (out / "sweep").glob("*/results.json")
    }
    report_of(out / "sweep", out / "report")
    return picked, jobs, out / "report"


@pytest.mark.slow
def test_a_tiny_selection_run_spends_what_each_point_states(tiny):
    picked, jobs, _ = tiny
    assert sorted(jobs) == sorted(picked)
    for name, res in jobs.items():
        assert res["status"] == "complete" and res["seeds"] == [0, 1] and res["config"]["eval"]["every"] == 1
        assert res["presentations_done"] == stated_cost(name)
        assert res["selection_presentations"] == (CHARGE if name == "b25_loss_high" else 0)
        assert res["training_presentations"] == res["schedule"]["presentations"]
    # the loss order and its partner spent the same, and 888 more than the stratified run and its partner
    assert jobs["b25_loss_high"]["presentations_done"] == jobs["b25_matched_charged"]["presentations_done"]
    extra = jobs["b25_loss_high"]["presentations_done"] - jobs["b25_stratified"]["presentations_done"]
    assert extra == CHARGE
    # the curve is scored at every epoch: 5 stages x 16 epochs + the untrained network
    assert len(jobs["b25_stratified"]["curves"]) == 81


@pytest.mark.slow
def test_the_report_pairs_the_stratified_run_with_conventional_training_at_its_cost(tiny):
    _, _, report = tiny
    rows = (report / "selection.csv").read_text().splitlines()
    (row,) = [r for r in rows if r.startswith("6-4-2,stratified,37632,")]
    assert ",matched schedule.budget=37632,1.0,2," in row


@pytest.mark.slow
def test_the_report_pairs_a_loss_order_with_conventional_training_at_its_total_cost(tiny):
    _, _, report = tiny
    rows = (report / "selection.csv").read_text().splitlines()
    (row,) = [r for r in rows if r.startswith("6-4-2,loss_high,")]
    assert ",matched schedule.budget=38520," in row
