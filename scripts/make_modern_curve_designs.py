"""Writes configs/design/modern_curve/: the learning curves that size experiment=modern (issue 28).

Conventional training of each arm and regime at doubling budgets N, 2N, 4N, ... epochs, one job each, run by
experiment=modern_curve on the validation draw (data.test_seed=1, seeds apart from the study's). The study's N is
the budget where doubling it changes the final held-out RMS by less than 10 % (or the largest that fits); it is
written into make_modern_designs.py (EPOCHS). The regimes and arms are that script's; the Adam rates are the ones
the curves ran at (CURVE_LR).
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "configs" / "design" / "modern_curve"
MODERN = runpy.run_path(str(Path(__file__).with_name("make_modern_designs.py")))
# arm -> the doubling budgets (epochs): from the old study's N up to where a job still takes about a minute
BUDGETS = {"two_link": [20 * 2**k for k in range(8)], "puma560": [5 * 2**k for k in range(7)]}
# the Adam rates the curves ran at: the earlier study's (issue 22's, chosen at N = 20 / 5); experiment=modern_lr then
# chooses the rate again at the budget these curves give (make_modern_designs.ADAM_LR)
CURVE_LR = {"two_link": 0.01, "puma560": 0.003}


def design(arm: str, regime: str, N: int) -> str:
    n = MODERN["ARMS"][arm][2]
    overrides, reg, what = MODERN["regime_lines"](regime, arm, CURVE_LR[arm])
    line = f"experiment=modern_curve: conventional training for N = {N} epochs ({n * N:,} presentations)"
    return "\n".join(
        [
            *MODERN["header"](arm, what, line, "make_modern_curve_designs.py"),
            "  - override /schedule: conventional",
            *overrides,
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
    for arm, budgets in BUDGETS.items():
        for regime in MODERN["REGIMES"]:
            for N in budgets:
                (out / f"{arm}_{regime}_N{N:04d}.yaml").write_text(design(arm, regime, N))
                count += 1
    print(f"wrote {count} files into {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
