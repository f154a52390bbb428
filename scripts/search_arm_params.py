"""Search masses/lengths for which the paper's grid keeps exactly 1002 patterns (the paper gives none).

Candidates are drawn so that the gravity torques at θ = 0 fall inside the commanded torque boxes (the paper
chose the boxes "based on a few tests using the inverse dynamic model"), then the full 1,050,625-candidate grid
is simulated and filtered. Prints each candidate's pattern count, gravity torques and boundary margin
(smallest | |θ̈| − accel_limit | over the grid: tiny margins make the count depend on rounding).

    python scripts/search_arm_params.py [--n 60] [--seed 0] [--target 1002] [--spread 0.05 | --wide]
"""

from __future__ import annotations

import argparse
import time

import torch
from omegaconf import OmegaConf

from selpres.arms.two_link import TwoLinkArm
from selpres.data.paper import accel_filter, grid_accelerations
from selpres.run.config import CONFIG_DIR


def evaluate(arm: TwoLinkArm, cfg) -> tuple[int, float, torch.Tensor]:
    """(pattern count, boundary margin, gravity torques at θ = 0) for one arm on the configured grid."""
    qdd = grid_accelerations(arm, cfg)[-1]
    count = int(accel_filter(qdd, cfg.accel_limit).sum())
    margin = float((qdd.abs() - cfg.accel_limit).abs().min())
    return count, margin, arm.gravity(torch.zeros(2, dtype=torch.float64))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=60, help="random candidates to try")
    ap.add_argument("--spread", type=float, default=0.05, help="relative neighbourhood of the local search")
    ap.add_argument("--wide", action="store_true", help="draw anywhere with gravity torques inside the boxes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--target", type=int, default=1002)
    ap.add_argument("--tolerance", type=int, default=20, help="also list counts this close to the target")
    ap.add_argument("--g", type=float, default=9.81)
    args = ap.parse_args()
    cfg = OmegaConf.load(CONFIG_DIR / "data/paper.yaml")
    robot = OmegaConf.load(CONFIG_DIR / "robot/two_link.yaml")

    count, margin, G = evaluate(TwoLinkArm.from_config(robot), cfg)
    print(
        f"current configs/robot/two_link.yaml {dict(robot)}: count={count} "
        f"G(0)=({G[0]:.3f}, {G[1]:.3f}) Nm margin={margin:.2e}"
    )

    gen = torch.Generator().manual_seed(args.seed)
    u = lambda lo, hi: lo + (hi - lo) * float(torch.rand((), dtype=torch.float64, generator=gen))
    base = TwoLinkArm.from_config(robot)
    hits, seen, t0 = [], set(), time.perf_counter()
    for _ in range(args.n):
        if args.wide:
            # lengths and gravity torques at θ = 0 anywhere inside the boxes; masses solved from them
            l1, l2 = round(u(0.1, 0.6), 2), round(u(0.1, 0.6), 2)
            m2 = round(u(cfg.tau2.lo, cfg.tau2.hi) / (l2 * args.g), 2)
            m1 = round((u(cfg.tau1.lo, cfg.tau1.hi) - m2 * l2 * args.g) / (l1 * args.g) - m2, 2)
        else:
            # local search: each parameter within ±spread of the current config, on a 0.01 grid
            m1, m2, l1, l2 = (
                round(v * u(1 - args.spread, 1 + args.spread), 2) for v in (base.m1, base.m2, base.l1, base.l2)
            )
        if min(m1, m2, l1, l2) <= 0 or (m1, m2, l1, l2) in seen:
            continue
        seen.add((m1, m2, l1, l2))
        arm = TwoLinkArm(m1, m2, l1, l2, args.g)
        count, margin, G = evaluate(arm, cfg)
        if not (cfg.tau1.lo <= G[0] <= cfg.tau1.hi and cfg.tau2.lo <= G[1] <= cfg.tau2.hi):
            continue
        if abs(count - args.target) <= args.tolerance:
            hits.append((abs(count - args.target), -margin, arm, count, margin, G))
    hits.sort(key=lambda h: h[:2])
    print(
        f"{args.n} candidates in {time.perf_counter() - t0:.1f} s; within ±{args.tolerance} of {args.target} "
        "(exact first, widest margin first):"
    )
    for _, _, arm, count, margin, G in hits[:25]:
        print(
            f"  m1={arm.m1:.2f} m2={arm.m2:.2f} l1={arm.l1:.2f} l2={arm.l2:.2f}: count={count} "
            f"G(0)=({G[0]:.3f}, {G[1]:.3f}) Nm margin={margin:.2e}"
        )


if __name__ == "__main__":
    main()
