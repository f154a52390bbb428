"""Writes configs/design/modern/: the design points of experiment=modern (2 arms x 3 regimes x 12 methods, + SeTa
on the cost's clock where the rate decays).

Run again after changing a value below; every file states its cost and its seeds. The costs are worked out here the
way selpres.presentation.proportions applies the paper's counts to n (fractions c/1002 of n, rounded half up; a
budget b scaled to b n / 1002), so the budget-form methods cost what selective presentation costs.

The epochs N and the Adam rate of each arm are chosen together (issue 40), on the validation draw, never on the
test sets the study reports: the learning curve at the rate (experiment=modern_curve, conventional training at
doubling budgets, scripts/make_modern_curve_designs.py) gives N, the smallest budget whose doubling moves the
median final held-out RMS by less than 10 %; the rate is chosen again at that N (experiment=modern_lr: the lowest
median of {0.001, 0.003, 0.01, 0.03}); iterated until neither moves. Both are written below by hand, with the
date and the rounds: decisions, taken on data the study does not report.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "configs" / "design" / "modern"
PAPER_N, PAPER_SIZES = 1002, (50, 100, 400, 800)
# arm -> (robot, topology, n)
ARMS = {"two_link": ("two_link", "6-13-2", 10_000), "puma560": ("puma560", "18-40-6", 100_000)}
# the paper's regime, Adam + ReLU (the modern one), and the remedy for its dead units: the same Adam regime (rate,
# budget, seeds) with leaky ReLU units, so that exactly one thing changes (selpres/engines/activations/leaky_relu.py)
REGIMES = ("paper", "adam", "adam_leaky")
ACTIVATION = {"adam": "relu", "adam_leaky": "leaky_relu"}
# (arm, regime) -> the study's epochs N (a multiple of 5: selective presentation's five stages of N/5 epochs); the
# remedy runs at its Adam regime's. 2026-12-07, validation draw (docs/studies/modern.md, "Rate and budget"):
#   two-link, Adam: the curve at 0.003 gives N = 320 (160 -> 320 moves the median -3.1 % but 8 seeds stalled at 160
#     and not at 320, McNemar p = 0.008: still training; 320 -> 640: -2.9 %, 0 / 0), and the rate check at 320 keeps
#     0.003 (median 0.731 Nm; 0.01: 0.775, 0.001: 0.978, 0.03: 3.03): one round;
#   PUMA 560, Adam: the curve at 0.003 gives N = 20 (20 -> 40: -0.5 %, stalls 2 / 0, p = 0.5), the rate check at 20
#     keeps 0.003 (1.031 Nm; 0.001: 1.072, 0.01: 2.717, 0.03: 3.146): one round;
#   the paper's regime (its lr 0.15, not searched): the two-link curve moves its median by more than 10 % at every
#     doubling up to 640 (-12.9 % at 160 -> 320, -11.1 % at 320 -> 640): no N <= 640 passes the rule, so it runs at
#     the largest N that fits the study's 30 minutes with its 2 x 48 seeds: 320 (640 would add ~3 minutes), a budget
#     the rule rejects; 640 with 2 x 24 seeds would cost the same (a choice, said in docs/studies/modern.md). The
#     PUMA 560's passes at 80 (-3.3 % at 80 -> 160, 12 seeds) and runs there. (A first cut to 50 epochs and
#     2 x 12 seeds was sized on timings taken at load 4-8; on 2 free cores the study at these budgets fits its
#     30 minutes: docs/studies/modern.md, "Time".)
EPOCHS = {("two_link", "paper"): 320, ("two_link", "adam"): 320, ("puma560", "paper"): 80, ("puma560", "adam"): 20}
# arm -> the Adam rate (its remedy's too), chosen with the budget above
ADAM_LR = {"two_link": 0.003, "puma560": 0.003}
# (arm, regime) -> replicas per job; every design point runs in two jobs (SEED_BLOCKS), so twice this many paired
# seeds (issue 40: at least 48 where a ~10 % stall rate would widen the intervals, the Adam cells; more where the
# margins need it and the runs are cheap: the two-link arm in the paper's regime, whose paired differences spread
# most against its margin). The PUMA 560 in the paper's regime, which stalled 0 of 48 seeds in every method at 60
# epochs, runs 2 x 24 = 48 as the Adam cells do
REPLICAS = {("two_link", "paper"): 48, ("two_link", "adam"): 24, ("puma560", "paper"): 24, ("puma560", "adam"): 24}
SEED_BLOCKS = (0, 1000)  # experiment=modern's seed values: seeds 0.. and 1000.. (apart from the curves' 100..)
# the held-out curve: about this many points per run (Selective Backprop's cost to reach an error is read off it)
CURVE_POINTS = 40
# method -> (the schedule it runs, its form): "full" trains for conventional's N epochs (the method's own claim,
# at its own saving), "budget" is stopped at selective presentation's cost (compute-matched), "staged" runs the
# five stages of N/5 epochs
METHODS = {
    "conventional": ("conventional", "full"),
    "selective": ("selective", "staged"),
    "matched": ("matched", "budget"),
    "random_growth": ("random_growth", "staged"),
    "infobatch": ("infobatch", "budget"),
    "infobatch_full": ("infobatch", "full"),
    "selective_backprop": ("selective_backprop", "budget"),
    "selective_backprop_full": ("selective_backprop", "full"),
    "seta": ("seta", "budget"),
    "seta_full": ("seta", "full"),
    "seta_random": ("seta_random", "budget"),
    "seta_random_full": ("seta_random", "full"),
    "seta_full_cost_clock": ("seta", "full"),  # where the rate decays: SeTa on the cost's clock, as before
}
# Each rival's learning-rate clock, where the rate decays (the Adam regimes), as its authors run it: SeTa's code
# re-positions its OneCycle schedule at every epoch (examples/cifar/main.py: last_epoch = epoch x len(data)), so a
# pruned run's rate still reaches its end: the epochs' clock (optim.lr_schedule=cosine_epochs), for SeTa and its
# Dynamic Random control at full length. InfoBatch's steps its schedule per iteration over the full-length horizon
# and Selective Backprop's per step: the cost's clock (cosine), as every method stopped at a budget, whose schedule
# ends at that budget. seta_full_cost_clock is SeTa at full length on the cost's clock, reported beside.
EPOCH_CLOCK = {"seta_full", "seta_random_full"}
COST_CLOCK_ONLY = {"seta_full_cost_clock"}  # run only where the rate decays (it is seta_full where it does not)


def half_up(x: float) -> int:
    return max(1, math.floor(x + 0.5))


def selective_cost(n: int, N: int) -> int:
    sizes = [half_up(c / PAPER_N * n) for c in PAPER_SIZES] + [n]
    return sum(sizes) * (N // 5)


def paper_budget(target: int, n: int) -> tuple[int, int]:
    """The budget b (for the paper's n) whose scaling b n / 1002 lands nearest ``target``: (b, scaled)."""
    b = round(target * PAPER_N / n)
    return b, half_up(b * n / PAPER_N)


def regime_lines(regime: str, arm: str, lr: float | None = None) -> tuple[list[str], list[str], str]:
    if regime == "paper":
        return [], [], "the paper's regime: sigmoid units, online SGD (batch 1), lr 0.15, momentum 0.9, constant"
    lr = ADAM_LR[arm] if lr is None else lr
    act = ACTIVATION[regime]
    lines = ["model:", f"  activation: {act}", "optim:", f"  lr: {lr}"]
    units = {"relu": "ReLU hidden units", "leaky_relu": "leaky ReLU hidden units (slope 0.01: the remedy)"}[act]
    what = (
        f"mini-batch Adam (batch 32), {units}, linear output, lr {lr} (chosen with the budget on the validation "
        "draw: experiment=modern_curve, modern_lr) cosine-decayed to zero over the run's own budget"
    )
    return ["  - override /optim: adam_minibatch"], lines, what


def header(arm: str, what: str, line: str, script: str = "make_modern_designs.py") -> list[str]:
    robot, topology, n = ARMS[arm]
    return [
        "# @package _global_",
        f"# generated by scripts/{script}: edit it there, not here",
        f"# arm {arm} (n = {n:,}), {what};",
        f"# {line}",
        "defaults:",
        f"  - override /robot: {robot}",
        f"  - override /topology: {topology}",
    ]


def every(N: int) -> int:
    return max(1, N // CURVE_POINTS)


def base(regime: str) -> str:
    """The regime whose rate, budget and seeds a variant runs at (the remedy: its Adam regime's)."""
    return "adam" if regime == "adam_leaky" else regime


def epochs_of(arm: str, regime: str) -> int:
    return EPOCHS[(arm, base(regime))]


def design(arm: str, regime: str, method: str) -> str:
    n, N = ARMS[arm][2], epochs_of(arm, regime)
    schedule, form = METHODS[method]
    sel = selective_cost(n, N)
    b, scaled = paper_budget(sel, n)
    stage = N // 5
    lines, cost = {
        "full": ([f"epochs: [{N}]"], f"conventional's N = {N} epochs of n = {n:,} ({n * N:,} presentations"),
        "staged": ([f"epochs: [{stage}, {stage}, {stage}, {stage}, {stage}]"], f"{sel:,} presentations"),
        "budget": (["epochs: null", f"budget: {b}"], f"{scaled:,} presentations (budget {b} scaled by n/1002)"),
    }[form]
    if form == "full":
        cost += ")" if method == "conventional" else " at most; its own saving is recorded)"
    if schedule != "conventional" and form == "budget" and method != "matched":
        cost += ", stopped at selective's cost"
    overrides, reg, what = regime_lines(regime, arm)
    if regime != "paper" and method in EPOCH_CLOCK:
        reg += ["  lr_schedule: cosine_epochs"]
        cost += "; its rate on the epochs' clock, as its authors run it"
    if method in COST_CLOCK_ONLY:
        cost += "; its rate on the cost's clock (SeTa's authors run the epochs')"
    replicas = REPLICAS[(arm, base(regime))]
    blocks = " and ".join(f"{s0}..{s0 + replicas - 1}" for s0 in SEED_BLOCKS)
    return "\n".join(
        [
            *header(arm, what, f"experiment=modern, method {method}: {cost}"),
            f"  - override /schedule: {schedule}",
            *overrides,
            f"# seeds {blocks} (experiment=modern's seed={','.join(map(str, SEED_BLOCKS))}, {replicas} each)",
            f"replicas: {replicas}",
            "data:",
            f"  n: {n}",
            "schedule:",
            *([f"  name: {method}"] if method != schedule else []),
            *(f"  {line}" for line in lines),
            "eval:",
            f"  every: {every(N)}",
            *reg,
            "",
        ]
    )


def points() -> list[tuple[str, str, str]]:
    """Every (arm, regime, method) of the study."""
    return [
        (arm, regime, method)
        for arm in ARMS
        for regime in REGIMES
        for method in METHODS
        if not (method in COST_CLOCK_ONLY and regime == "paper")
    ]


def main(out: Path = OUT) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for arm, regime, method in points():
        (out / f"{arm}_{regime}_{method}.yaml").write_text(design(arm, regime, method))
    print(f"wrote {len(points())} files into {out}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="Write experiment=modern's design files (configs/design/modern).")
    parser.add_argument("out", nargs="?", type=Path, default=OUT, help=f"the folder to write into (default: {OUT})")
    main(parser.parse_args().out)
