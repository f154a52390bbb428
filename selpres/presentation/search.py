"""Schedules from a few numbers, for a search under a fixed presentation budget (issue 12 item 2).

A search over every list of stage sizes n_i and epochs N_i is too wide and mostly breaks the constraints
(sizes increasing, ending at n; the total within the budget). ``shaped_schedule`` maps four numbers onto a
valid schedule instead:

* ``p`` enlargements (p + 1 stages; p = 0 is conventional training cut to the budget, the compute-matched
  baseline, so a search can find that choosing does not pay);
* ``first`` = n_1 / n, and ``growth`` gamma: the fractions n_i / n = first + (1 - first) (i / p)^gamma,
  i = 0..p (gamma = 1 linear, > 1 slow start, < 1 fast start), rounded half up to counts;
* ``tilt``: stage i's share of the training presentations is proportional to exp(tilt i / p) (0: equal
  presentations per stage, > 0: more on the larger sets), so N_i = round(share_i T / n_i), at least 1, and
  the last stage takes what is left of T.

T is the budget less the cost of choosing (``selpres.presentation.orders``): a loss-based order charges its
forward passes at each enlargement, so every order spends the same total. The total lands within n/2
presentations of the budget (the last stage's rounding), or above it where every stage's minimum of one
epoch already exceeds it; results.json records the exact count either way.
"""

from __future__ import annotations

import math

from selpres.errors import ConfigError
from selpres.presentation.orders import planned_charge
from selpres.presentation.schedule import build_schedule

SEARCH_KEYS = ("search_p", "search_first", "search_growth", "search_tilt", "search_budget")


def shaped_sizes(p: int, first: float, growth: float, n: int) -> list[int]:
    """Stage sizes n_0 <= ... <= n_p = n from (p, first, growth). Where rounding merges two (small n, large
    first), they are returned merged: the job refuses them (``schedule.sizes`` must grow) and fails alone."""
    if p < 0 or not 0 < first <= 1 or not growth > 0:
        raise ConfigError(
            "search", {"p": p, "first": first, "growth": growth}, "p >= 0 enlargements, first in (0, 1], growth > 0"
        )
    if p == 0:
        return [n]
    return [max(1, math.floor((first + (1 - first) * (i / p) ** growth) * n + 0.5)) for i in range(p + 1)]


def shaped_schedule(
    p: int, first: float, growth: float, tilt: float, n: int, budget: int, order: str, selection_cost: float
) -> dict:
    """The schedule of (p, first, growth, tilt) at ``budget`` total presentations for ``order``, as
    ``schedule.*`` config values: {"sizes": [...], "epochs": [...] or None, "budget": None or int}."""
    sizes = shaped_sizes(p, first, growth, n)
    T = budget - planned_charge(order, sizes, selection_cost)
    if p == 0:  # conventional training cut to the budget (schedule.budget: whole epochs + a partial one)
        return {"sizes": [n], "epochs": None, "budget": T}
    weights = [math.exp(tilt * i / p) for i in range(p + 1)]
    shares = [w / sum(weights) * T for w in weights]
    epochs = [max(1, round(s / size)) for s, size in zip(shares[:-1], sizes[:-1])]
    rest = T - sum(e * size for e, size in zip(epochs, sizes))
    return {"sizes": sizes, "epochs": [*epochs, max(1, round(rest / n))], "budget": None}


def raw_schedule(raw: dict, n: int, order: str, selection_cost: float) -> dict:
    """The schedule (as ``shaped_schedule`` gives it) that the search numbers ``raw`` (SEARCH_KEYS ->
    value, as Optuna stores them) stand for."""
    return shaped_schedule(
        int(raw["search_p"]),
        float(raw["search_first"]),
        float(raw["search_growth"]),
        float(raw["search_tilt"]),
        n,
        int(raw["search_budget"]),
        order,
        selection_cost,
    )


def schedule_overrides(raw: dict, n: int, order: str, selection_cost: float) -> list[str]:
    """Hydra overrides of the schedule that the search numbers ``raw`` stand for."""
    fmt = lambda v: "null" if v is None else str(v).replace(" ", "")
    return [f"schedule.{k}={fmt(v)}" for k, v in raw_schedule(raw, n, order, selection_cost).items()]


def total_cost(schedule: dict, n: int, order: str, selection_cost: float) -> int:
    """What a run of ``schedule`` ({"sizes", "epochs", "budget"}) spends in all: its training presentations
    plus the charge for choosing. A compute-matched partner is conventional training stopped there."""
    sch = build_schedule(schedule["sizes"], schedule["epochs"], n, schedule["budget"])
    return sch.presentations + planned_charge(order, sch.sizes, selection_cost)


CONFIRM = "search-confirm"  # the sweep (outputs/sweeps/<name>) where the best schedule meets its partner
CONFIRM_SEEDS = (0, 30)  # seed, replicas: seeds 0..29, apart from the search seeds (experiment/search.yaml)


def confirmation_commands(best: list[tuple[dict, str]], n: int, selection_cost: float) -> list[str]:
    """Shell commands that confirm the schedules ``best`` [(search numbers, order)] stand for on fresh seeds
    and the held-out set (the default ``data.test_seed``): each schedule and conventional training stopped
    at its total cost (its compute-matched partner; p = 0, conventional cut to the budget, is its own); the
    paper's selective schedule and its partner (70,560), the reference the search set out to beat, which
    also gives the report's selection verdict two budgets to compare when only stratified or random orders
    are confirmed; the paper's conventional run (the time-to-target target); then the report. Every curve
    is scored each epoch; a partner two schedules share is run once."""
    seed, replicas = CONFIRM_SEEDS
    run = f"python train.py -m name={CONFIRM} seed={seed} replicas={replicas} eval.every=1"
    cmds: list[str] = []
    for raw, order in best:
        sched = raw_schedule(raw, n, order, selection_cost)
        staged = " ".join(f"'{o}'" for o in schedule_overrides(raw, n, order, selection_cost))
        cmds.append(f"{run} schedule.name=search schedule.order={order} {staged}")
        if len(sched["sizes"]) > 1:
            cost = total_cost(sched, n, order, selection_cost)
            cmds.append(f"{run} schedule=matched schedule.budget={cost}")
    cmds += [
        f"{run} schedule=selective",
        f"{run} schedule=matched schedule.budget=70560",
        f"{run} schedule=conventional",
    ]
    return [*dict.fromkeys(cmds), f"python -m selpres.report outputs/sweeps/{CONFIRM}"]
