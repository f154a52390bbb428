"""selpres-bench: the native kernel's build and exemplar-set generation."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from selpres_bench.common import CHILD_PATH, median_seconds


def bench_compile() -> None:
    """First-use build time of the native kernel: cold (empty cache) and cached (a new process's load)."""
    code = (
        "import time,torch;from selpres.native import load;t=time.perf_counter();"
        "load((6,13,2));print(time.perf_counter()-t)"
    )
    env = dict(os.environ, PYTHONPATH=CHILD_PATH)
    with tempfile.TemporaryDirectory() as tmp:
        env["SELPRES_CACHE_DIR"] = tmp
        out = []
        for _ in range(2):
            p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
            out.append(float(p.stdout.strip()) if p.returncode == 0 else float("nan"))
    print(f"\nnative kernel build (6-13-2): cold {out[0]:.2f} s, cached {out[1] * 1e3:.1f} ms (load of the .so)")


def bench_exemplar_generation(quick: bool, configs: Path) -> None:
    """The exemplar set (1,050,625 candidates, one batched forward-dynamics call) against a per-row
    Python loop over the same grid (math module, the closed-form 2x2 solve), extrapolated from a slice."""
    from omegaconf import OmegaConf

    from selpres.arms.two_link import TwoLinkArm
    from selpres.data.paper import build_exemplar_set, grid_axis

    rcfg, dcfg = OmegaConf.load(configs / "robot/two_link.yaml"), OmegaConf.load(configs / "data/paper.yaml")
    arm = TwoLinkArm.from_config(rcfg)
    reps = 3 if quick else 7
    ex = build_exemplar_set(arm, dcfg)
    batched = median_seconds(lambda: build_exemplar_set(arm, dcfg), reps)

    m1, m2, l1, l2, g, a = rcfg.m1, rcfg.m2, rcfg.l1, rcfg.l2, rcfg.g, dcfg.accel_limit
    axes = {k: grid_axis(dcfg[k].lo, dcfg[k].hi, dcfg[k].step).tolist() for k in ("theta", "dtheta", "tau1", "tau2")}
    states = [
        (q1, w1, q2, w2)
        for q1 in axes["theta"]
        for w1 in axes["dtheta"]
        for q2 in axes["theta"]
        for w2 in axes["dtheta"]
    ]
    torques = [(t1, t2) for t1 in axes["tau1"] for t2 in axes["tau2"]]
    total = len(states) * len(torques)
    limit = 40 if quick else 120  # states timed; the rest extrapolated
    kept, t0 = 0, time.perf_counter()
    for q1, w1, q2, w2 in states[:limit]:
        for t1, t2 in torques:
            c2, s2 = math.cos(q2), math.sin(q2)
            h11 = l2 * l2 * m2 + 2 * l1 * l2 * m2 * c2 + l1 * l1 * (m1 + m2)
            h12 = l2 * l2 * m2 + l1 * l2 * m2 * c2
            h22 = l2 * l2 * m2
            b1 = (
                -m2 * l1 * l2 * s2 * w2 * w2
                - 2 * m2 * l1 * l2 * s2 * w1 * w2
                + m2 * l2 * g * math.cos(q1 + q2)
                + (m1 + m2) * l1 * g * math.cos(q1)
            )
            b2 = m2 * l1 * l2 * s2 * w1 * w1 + m2 * l2 * g * math.cos(q1 + q2)
            det = h11 * h22 - h12 * h12
            a1 = (h22 * (t1 - b1) - h12 * (t2 - b2)) / det
            a2 = (h11 * (t2 - b2) - h12 * (t1 - b1)) / det
            kept += abs(a1) <= a and abs(a2) <= a
    loop = (time.perf_counter() - t0) * len(states) / limit
    print(f"\nexemplar set: {total:,} candidates -> {len(ex.X)} patterns")
    print(f"  batched torch (build_exemplar_set)  {batched * 1e3:9.1f} ms  (median of {reps})")
    print(
        f"  per-row Python loop                 {loop * 1e3:9.1f} ms  (extrapolated from {limit} of "
        f"{len(states)} states)  ratio x {loop / batched:.0f}"
    )
