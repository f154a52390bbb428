"""Check a URDF chain against Pinocchio: ``python -m selpres.arms.check FILE... [--base L] [--tip L]``.

For each file: what ``load_urdf`` models and holds (or the one line it refuses with), and the largest
|τ_selpres − τ_Pinocchio| over drawn states. Pinocchio (the ``robots`` extra: ``pin``) builds the whole file
and ``pin.buildReducedModel`` locks every joint selpres holds, at the value selpres holds it at, then its
RNEA gives the reference torques; a folder is searched for ``*.urdf``. ``tests/test_robot_files.py`` uses
the same comparison on published files from ``example-robot-data``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import torch

from selpres.errors import ConfigError


def pinocchio_torques(path: Path, arm, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor) -> np.ndarray:
    """Pinocchio's τ ``[B, N]`` for the arm's modelled joints, every other joint locked where selpres held it."""
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(path))
    q0, lock = pin.neutral(model), []
    for jid in range(1, model.njoints):
        name, j = model.names[jid], model.joints[jid]
        if name in arm.source["modelled"]:
            continue
        lock.append(jid)
        v = arm.source["held"].get(name, 0.0)
        if j.nq == 2:  # a continuous joint: (cos, sin)
            q0[j.idx_q : j.idx_q + 2] = [math.cos(v), math.sin(v)]
        elif j.nq == 1:
            q0[j.idx_q] = v
    red = pin.buildReducedModel(model, lock, q0)
    names = [red.names[i] for i in range(1, red.njoints)]
    if names != arm.source["modelled"]:
        raise ValueError(f"Pinocchio's reduced model has joints {names}, selpres {arm.source['modelled']}")
    data = red.createData()
    out = []
    for x, v, a in zip(q.numpy(), qd.numpy(), qdd.numpy()):
        qp = np.concatenate(
            [[math.cos(x[k]), math.sin(x[k])] if red.joints[k + 1].nq == 2 else [x[k]] for k in range(arm.dof)]
        )
        out.append(pin.rnea(red, data, qp, v, a).copy())
    return np.array(out)


def drawn_states(dof: int, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """q in [-π, π], q̇ and q̈ standard normal (float64)."""
    g = torch.Generator().manual_seed(seed)
    q = (torch.rand(n, dof, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    return (
        q,
        torch.randn(n, dof, generator=g, dtype=torch.float64),
        torch.randn(n, dof, generator=g, dtype=torch.float64),
    )


def check(path: Path, n: int = 60, **chain) -> str:
    """One line: the file, modelled / held joints and the largest torque difference, or why it is refused."""
    from selpres.arms.urdf import load_urdf

    try:
        arm = load_urdf(path, **chain)
    except ConfigError as e:
        return f"{path}: refused: {str(e).removeprefix(f'{path}: ')}"
    q, qd, qdd = drawn_states(arm.dof, n, 7)
    try:
        ref = pinocchio_torques(path, arm, q, qd, qdd)
    except (ValueError, RuntimeError) as e:  # Pinocchio's own refusals (e.g. two frames of one name)
        return f"{path}: {arm.dof} modelled, {len(arm.source['held'])} held; Pinocchio failed: {e}"
    err = np.abs(arm.inverse_dynamics(q, qd, qdd).numpy() - ref).max()
    return f"{path}: {arm.dof} modelled, {len(arm.source['held'])} held, max |tau - Pinocchio| {err:.2g} Nm"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python -m selpres.arms.check", description=__doc__.split("\n")[0])
    p.add_argument("paths", nargs="+", type=Path, help="URDF files or folders to search for *.urdf")
    p.add_argument("--base", default=None, help="robot.base: the link the chain starts from")
    p.add_argument("--tip", default=None, help="robot.tip: the link the chain ends at")
    p.add_argument("--states", type=int, default=60, help="drawn states per file (default 60)")
    args = p.parse_args(argv)
    files = [f for x in args.paths for f in (sorted(x.rglob("*.urdf")) if x.is_dir() else [x])]
    for f in files:
        print(check(f, args.states, base=args.base, tip=args.tip), flush=True)


if __name__ == "__main__":
    main()
