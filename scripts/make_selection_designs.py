"""Writes configs/design/selection/: the 25 design points of experiment=selection (3 budgets x (6 orders
+ 2 compute-matched partners) + conventional). Run again after changing a value below; every file states its
cost, worked out here as selpres.presentation.selection charges it (candidates scored at an enlargement x
schedule.selection_cost 1/3, rounded up per enlargement), and tests/test_design_grids.py checks the files on disk
are exactly what this writes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "configs" / "design" / "selection"
N_PAPER, SIZES, CONVENTIONAL = 1002, (50, 100, 400, 800, 1002), 150
BUDGETS = {"b25": 16, "b47": 30, "b75": 48}  # name -> N_i of each of the paper's five stages
# order -> (schedule.name, what each A_i is); the loss orders also pay for scoring the candidates
ORDERS = {
    "stratified": ("selective", "each A_i a proportional stratified sample of U (the paper's uniform sampling)."),
    "random": ("random_growth", "each A_i a random prefix of U (random growth)."),
    "coverage": ("coverage", "each A_i a prefix of U's greedy farthest-point order (a near-minimal-radius cover)."),
    "loss_high": (
        "loss_high",
        "A_1 stratified, then each enlargement adds the patterns of U \\ A_i the current\n"
        "#   network errs most on (hard first).",
    ),
    "loss_low": (
        "loss_low",
        "A_1 stratified, then each enlargement adds the patterns of U \\ A_i the current\n"
        "#   network errs least on (easy first).",
    ),
    "reselect": ("reselect", "each A_i a fresh stratified draw of its size (not nested)."),
}
LOSS_ORDERS = ("loss_high", "loss_low")


def charged() -> tuple[list[int], list[int]]:
    """The candidates scored at each enlargement (U minus A_i) and what each costs at 1/3, rounded up."""
    candidates = [N_PAPER - s for s in SIZES[:-1]]
    return candidates, [math.ceil(c / 3) for c in candidates]


def stages_line(Ni: int, training: int) -> str:
    share = 100 * training / (N_PAPER * CONVENTIONAL)
    return (
        f"# The paper's stages n_i = {', '.join(map(str, SIZES))} with N_i = {Ni} each: {share:.2f} % of "
        f"{N_PAPER * CONVENTIONAL:,}."
    )


def staged(budget: str, order: str) -> str:
    Ni = BUDGETS[budget]
    training = sum(SIZES) * Ni
    name, what = ORDERS[order]
    lines = ["# @package _global_", f"# Order {order}: {what}", stages_line(Ni, training)]
    if order in LOSS_ORDERS:
        cand, cost = charged()
        lines += [
            f"# cost: {training + sum(cost):,} presentations",
            f"# ({training:,} training + {sum(cost)} charged for choosing: the {' + '.join(map(str, cand))} "
            "candidates scored at",
            f"# the four enlargements x 1/3, rounded up per enlargement, {' + '.join(map(str, cost))})",
        ]
    else:
        lines.append(f"# cost: {training:,} presentations")
    epochs = ", ".join([str(Ni)] * len(SIZES))
    lines += ["defaults:", "  - override /schedule: selective", "schedule:", f"  name: {name}"]
    return "\n".join([*lines, f"  epochs: [{epochs}]", f"  order: {order}", ""])


def matched(budget: str, with_charge: bool) -> str:
    Ni = BUDGETS[budget]
    training = sum(SIZES) * Ni
    share = 100 * training / (N_PAPER * CONVENTIONAL)
    extra = sum(charged()[1]) if with_charge else 0
    total = training + extra
    partner = (
        f"the partner of the loss orders ({training:,} training + {extra} charged for choosing):"
        if with_charge
        else "the partner of the stratified, random, coverage and reselect orders:"
    )
    epochs, rest = divmod(total, N_PAPER)
    return "\n".join(
        [
            "# @package _global_",
            f"# Compute-matched conventional training at {share:.2f} % of {N_PAPER * CONVENTIONAL:,},",
            f"# {partner}",
            f"# all n = {N_PAPER} patterns, stopped after {total:,} presentations ({epochs} epochs + {rest}).",
            f"# cost: {total:,} presentations",
            "defaults:",
            "  - override /schedule: matched",
            "schedule:",
            f"  budget: {total}",
            "",
        ]
    )


CONVENTIONAL_FILE = """# @package _global_
# The paper's conventional training (Table 1): all n = 1002 patterns, N = 150 epochs. Its final
# held-out error is the target of "presentations to conventional's final".
# cost: 150,300 presentations
defaults:
  - override /schedule: conventional
"""


def designs() -> dict[str, str]:
    """file name -> its text, every point of the grid."""
    out = {"conventional.yaml": CONVENTIONAL_FILE}
    for b in BUDGETS:
        out |= {f"{b}_{o}.yaml": staged(b, o) for o in ORDERS}
        out[f"{b}_matched.yaml"] = matched(b, False)
        out[f"{b}_matched_charged.yaml"] = matched(b, True)
    return out


def main(out: Path = OUT) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for name, text in designs().items():
        (out / name).write_text(text)
    print(f"wrote {len(designs())} design points to {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
