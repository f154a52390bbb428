"""Writes configs/design/modern_curve/: the learning curves that size experiment=modern (issues 28, 40).

Conventional training of each arm and regime at doubling budgets N, 2N, 4N, ... epochs, one job each, run by
experiment=modern_curve on the validation draw (data.test_seed=1, seeds 100.. apart from the study's), at the rate
the study runs (make_modern_designs.ADAM_LR; the paper's regime at its lr 0.15). The study's N is the budget where
doubling it changes the median final held-out RMS by less than 10 % (or the largest that fits); experiment=modern_lr
then checks the rate at that N; the two are iterated until neither moves, and written into make_modern_designs.py
(EPOCHS, ADAM_LR). The regimes and arms are that script's; the remedy (adam_leaky) runs at its Adam
regime's rate and budget, so it has no curve of its own.
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "configs" / "design" / "modern_curve"
MODERN = runpy.run_path(str(Path(__file__).with_name("make_modern_designs.py")))
# (arm, regime) -> the doubling budgets (epochs): from below the study's N to past the doubling that confirms it
BUDGETS = {
    ("two_link", "paper"): [20 * 2**k for k in range(6)],  # 20 .. 640
    ("two_link", "adam"): [20 * 2**k for k in range(6)],  # 20 .. 640
    ("puma560", "paper"): [5 * 2**k for k in range(6)],  # 5 .. 160
    ("puma560", "adam"): [5 * 2**k for k in range(4)],  # 5 .. 40: the rule gives 20, 40 confirms it (issue 40's time)
}
# (arm, regime) -> seeds per curve point (100..): the stall rate per budget needs more where stalls are common
REPLICAS = {("two_link", "paper"): 48, ("two_link", "adam"): 48, ("puma560", "paper"): 12, ("puma560", "adam"): 24}


def design(arm: str, regime: str, N: int) -> str:
    n = MODERN["ARMS"][arm][2]
    overrides, reg, what = MODERN["regime_lines"](regime, arm)
    line = f"experiment=modern_curve: conventional training for N = {N} epochs ({n * N:,} presentations)"
    replicas = REPLICAS[(arm, regime)]
    return "\n".join(
        [
            *MODERN["header"](arm, what, line, "make_modern_curve_designs.py"),
            "  - override /schedule: conventional",
            *overrides,
            f"# seeds 100..{100 + replicas - 1} (experiment=modern_curve's seed=100)",
            f"replicas: {replicas}",
            "data:",
            f"  n: {n}",
            "schedule:",
            f"  epochs: [{N}]",
            "eval:",
            f"  every: {MODERN['every'](N)}",
            *reg,
            "",
        ]
    )


def main(out: Path = OUT) -> None:
    out.mkdir(parents=True, exist_ok=True)
    count = 0
    for (arm, regime), budgets in BUDGETS.items():
        for N in budgets:
            (out / f"{arm}_{regime}_N{N:04d}.yaml").write_text(design(arm, regime, N))
            count += 1
    print(f"wrote {count} files into {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
