"""experiment=sensitivity: the sweep composes, every design point is a valid job of its family at the cost its
file states, and a tiny version runs end to end through the documented command and the report.

Composing a design point takes ~0.15 s, so the fast tier checks one point of every family at each cost;
the checks over all 148 points (each validated and prepared, the families' grids, no job twice) are slow."""

from __future__ import annotations

import functools
import json
import re

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import Glob
from omegaconf import OmegaConf

from selpres.engines.optim import OPTIMIZERS
from selpres.run.problem import prepare
from selpres.run.resolve import resolve
from selpres.run.results import job_hash
from selpres.run.specs import plain as to_container

from conftest import CONFIGS, cfg_of, compose, report_of, run_python

DESIGN = CONFIGS / "design"
EXPERIMENT = CONFIGS / "experiment" / "sensitivity.yaml"
N = 1002  # the exemplar set's size (configs/robot/two_link.yaml + configs/data/paper.yaml)
PAPER_COST, SELECTIVE_COST = 150 * N, 70_560  # conventional 150 epochs; the paper's selective schedule
RIVALS = {"sgd": "sgd", "qp": "quickprop", "dbd": "delta_bar_delta", "adam": "adam", "rprop": "rprop"}
SWEPT = {
    "sgd": ("lr", "momentum"),
    "quickprop": ("lr", "mu"),
    "delta_bar_delta": ("kappa", "phi", "theta"),
    "adam": ("lr",),
    "rprop": ("lr", "eta_plus"),
}  # the critical parameters each rival is swept over


def design_files() -> list[str]:
    return sorted(p.stem for p in DESIGN.glob("*.yaml"))


def design_points(value: str | None = None) -> list[str]:
    """The design points a ``design=<value>`` sweep runs (default: the experiment's own list), in its order,
    parsed by Hydra's override parser: a list of names, or a glob over the files of configs/design/."""
    value = value or OmegaConf.load(EXPERIMENT).hydra.sweeper.params.design
    override = OverridesParser.create().parse_overrides([f"design={value}"])[0]
    if isinstance(override.value(), Glob):
        return override.value().filter(design_files())
    return list(override.sweep_string_iterator())


def stated_cost(point: str) -> int:
    """The cost a design file states on its line "# cost: N presentations"."""
    (cost,) = re.findall(r"^# cost: ([\d,]+) presentations$", (DESIGN / f"{point}.yaml").read_text(), re.M)
    return int(cost.replace(",", ""))


def presentations(sch: dict) -> int:
    """T/t from a composed schedule: sum n_i N_i (a fraction of n rounded half up), or the budget."""
    sizes = [int(s * N + 0.5) if isinstance(s, float) else s for s in sch["sizes"]]
    return sch["budget"] if sch["budget"] is not None else sum(n * e for n, e in zip(sizes, sch["epochs"]))


@functools.cache
def composed(name: str):
    """A design point's config as ``python train.py experiment=sensitivity design=<name>`` composes it, with
    a small held-out set (composed once per test session; nothing here modifies it)."""
    return cfg_of("experiment=sensitivity", f"design={name}")


def point(name: str) -> dict:
    """A design point's composed config as plain values."""
    return to_container(composed(name))


def family(name: str) -> str:
    return name.split("_", 1)[0]


POINTS = design_points()
# the fast tier's points: the paper's two runs and one point of every family at each of its costs
REPRESENTATIVE = {
    "sel_paper",
    "sel_p1",
    "matched_78900",
    "sgd_c150300_lr0.15_m0.9",
    "sgd_c70560_lr0.15_m0.9",
    "qp_c150300_eps0.003_mu2.25",
    "qp_c70560_eps0.001_mu1.75",
    "dbd_c150300_k0.01_phi0.8_th0.9",
    "dbd_c70560_k0.001_phi0.2_th0.5",
    "adam_c150300_lr0.3",
    "adam_c70560_lr0.001",
    "rprop_c150300_lr1_etap1.5",
    "rprop_c70560_lr0.01_etap1.1",
}


def test_the_experiment_is_a_two_at_a_time_multirun_of_ten_paired_seeds_under_outputs_sweeps():
    cfg = compose("experiment=sensitivity", hydra=True)
    assert (cfg.name, cfg.seed, cfg.replicas, cfg.threads) == ("sensitivity", 0, 10, 1)
    assert cfg.topology.layers == "6-13-2"
    assert cfg.hydra.mode.name == "MULTIRUN" and cfg.hydra.launcher.n_jobs == 2
    assert cfg.hydra.sweep.dir == "outputs/sweeps/sensitivity"


def test_every_design_file_is_swept_once_and_the_job_count_is_the_documented_one():
    files = design_files()
    assert len(set(POINTS)) == len(POINTS), "a design point listed twice"
    assert not set(POINTS) - set(files), f"listed without a file: {sorted(set(POINTS) - set(files))}"
    assert sorted(POINTS) == files, f"design files the sweep misses: {sorted(set(files) - set(POINTS))}"
    (documented,) = re.findall(r"^# Jobs: .* = (\d+)\.$", EXPERIMENT.read_text(), re.M)
    assert len(POINTS) == int(documented)
    assert REPRESENTATIVE <= set(POINTS)
    assert {family(p) for p in REPRESENTATIVE} == {family(p) for p in POINTS}
    # a part of the study, as the experiment's comment shows: 'design=glob([sel_*,matched_*])'
    part = sorted(p for p in POINTS if family(p) in ("sel", "matched"))
    assert design_points("glob([sel_*,matched_*])") == part


def test_the_grid_is_the_generators_and_the_experiment_lists_no_names(tmp_path):
    """scripts/make_sensitivity_designs.py, run again, writes exactly the design files there are (selective
    presentation's 15 points and 13 partners, the rivals' 120: no file edited by hand, none missing or extra), and
    the experiment sweeps them by glob, not by a list of names."""
    done = run_python("scripts/make_sensitivity_designs.py", str(tmp_path))
    assert done.returncode == 0, done.stderr
    made = {p.name: p.read_text() for p in tmp_path.glob("*.yaml")}
    have = {p.name: p.read_text() for p in DESIGN.glob("*.yaml")}
    assert len(made) == 148 == len(POINTS) and sorted(made) == sorted(have)
    assert [n for n in made if made[n] != have[n]] == []
    text = EXPERIMENT.read_text()
    assert not [p for p in POINTS if p in text.split("hydra:")[1]], "design names listed in the experiment"


def test_costs_worked_by_hand():
    by_hand = {
        "sel_paper": 70_560,  # Table 1: 50·30 + 100·30 + 400·30 + 800·30 + 1002·30
        #                        = 1,500 + 3,000 + 12,000 + 24,000 + 30,060
        "sel_p3": 58_980,  # 50·37 + 136·37 + 369·38 + 1002·38 = 1,850 + 5,032 + 14,022 + 38,076
        "sel_Ni_decreasing": 44_520,  # 50·50 + 100·40 + 400·30 + 800·20 + 1002·10
        #                                = 2,500 + 4,000 + 12,000 + 16,000 + 10,020
        "sgd_c150300_lr0.15_m0.9": 150_300,  # 1002·150, Table 1's conventional run
        "qp_c70560_eps0.001_mu1.75": 70_560,  # a budget: 70 epochs of 1002 (70,140) + 420 of the 71st
    }
    for name, cost in by_hand.items():
        assert prepare(resolve(composed(name))).schedule.presentations == cost


@pytest.mark.parametrize(
    "name", [n if n in REPRESENTATIVE else pytest.param(n, marks=pytest.mark.slow) for n in POINTS]
)
def test_each_design_point_validates_and_costs_what_its_file_says(name):
    cfg = composed(name)
    sch = prepare(resolve(cfg)).schedule
    assert sch.presentations == stated_cost(name) == presentations(point(name)["schedule"])


@pytest.mark.slow
def test_the_selective_family_varies_only_its_schedule_and_each_cost_has_a_budget_matched_partner():
    sel = [p for p in POINTS if family(p) == "sel"]
    assert len(sel) == 15 and "sel_paper" in sel
    matched = {}  # budget -> the one-stage online SGD point (the paper's lr and momentum) stopped there
    for name in POINTS:
        c = point(name)
        if family(name) in ("matched", "sgd") and c["schedule"]["budget"] is not None:
            if (c["optim"]["lr"], c["optim"]["momentum"]) == (0.15, 0.9):
                matched[c["schedule"]["budget"]] = name
    for name in sel:
        c = point(name)
        assert c["schedule"]["name"] == "selective" and len(c["schedule"]["sizes"]) >= 2, name
        assert c["optim"] == point("sel_paper")["optim"], f"{name}: only the schedule varies"
        assert c["schedule"]["sizes"][-1] == N and sum(c["schedule"]["epochs"]) in (75, 150, 300), name
        assert stated_cost(name) in matched, f"{name}: no budget-matched conventional run"
    ps = sorted(len(point(p)["schedule"]["sizes"]) - 1 for p in sel if re.fullmatch(r"sel_p\d", p))
    assert ps == [1, 2, 3, 4, 5, 6]
    assert sorted(matched) == sorted({stated_cost(p) for p in sel}), "a matched run with no selective partner"


@pytest.mark.slow
def test_every_rival_runs_its_whole_grid_at_the_papers_cost_and_at_the_selective_cost():
    for prefix, optim in RIVALS.items():
        grid: dict[int, set] = {PAPER_COST: set(), SELECTIVE_COST: set()}
        for name in (p for p in POINTS if family(p) == prefix):
            c = point(name)
            assert OPTIMIZERS.canonical(c["optim"]["_target_"]) == optim and len(c["schedule"]["sizes"]) == 1, name
            assert c["schedule"]["name"] == ("conventional" if stated_cost(name) == PAPER_COST else "matched")
            grid[stated_cost(name)].add(tuple(c["optim"][k] for k in SWEPT[optim]))
        assert grid[PAPER_COST] == grid[SELECTIVE_COST] and len(grid[PAPER_COST]) >= 5, prefix
        for values in zip(*grid[PAPER_COST]):  # each critical parameter takes >= 3 values
            assert len(set(values)) >= 3 or len(SWEPT[optim]) == 1, prefix
    assert (0.15, 0.9) in {
        (point(p)["optim"]["lr"], point(p)["optim"]["momentum"]) for p in POINTS if family(p) == "sgd"
    }  # the paper's own setting is in the SGD grid


@pytest.mark.slow
def test_no_two_design_points_are_the_same_job():
    hashes = {}
    for name in POINTS:
        h = job_hash(composed(name))
        assert h not in hashes, f"{name} and {hashes.get(h)} compose the same job"
        hashes[h] = name


@pytest.mark.slow
def test_a_tiny_sweep_runs_end_to_end_and_reports(tmp_path):
    """The documented command on four design points (one per kind), 2 seeds, a small held-out set."""
    picked = ["sel_p1", "matched_78900", "qp_c70560_eps0.001_mu1.75", "sgd_c70560_lr0.15_m0.9"]
    sweep = tmp_path / "sweep"
    out = run_python(
        "train.py",
        "experiment=sensitivity",
        f"design=glob([{','.join(picked)}])",
        "replicas=2",
        "data.heldout=200",
        "eval.heldout_curve=200",
        "logging.progress=false",
        f"hydra.sweep.dir={sweep}",
    )
    assert out.returncode == 0, out.stderr[-3000:]
    # a job's folder is named by its overrides, the design point among them
    jobs = {
        re.search(r"(?:^|,)design=([^,]+)", p.parent.name).group(1): json.loads(p.read_text())
        for p in sweep.glob("*/results.json")
    }
    assert sorted(jobs) == sorted(picked)
    for name in picked:
        res = jobs[name]
        assert res["status"] == "complete" and res["seeds"] == [0, 1]
        assert res["presentations_done"] == res["schedule"]["presentations"] == stated_cost(name)
        assert res["config"]["optim"]["_target_"] == OPTIMIZERS.canonical(point(name)["optim"]["_target_"])
    report_of(sweep, tmp_path / "r")
    assert (tmp_path / "r" / "report.md").is_file()
