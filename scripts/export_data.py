"""Build the exemplar set and test sets from the configs and export them (npz + full-precision CSVs).

    python scripts/export_data.py [out_stem] [robot.KEY=VALUE ...] [data.KEY=VALUE ...] [seed=N]

Defaults: configs/robot/two_link.yaml, configs/data/paper.yaml, seed=0, out_stem=outputs/data/exemplar.
Also prints the scaled target ranges of both scaling modes (the reason 'exemplar' is the default).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from selpres import data as D  # noqa: E402
from selpres.robot import TwoLinkArm  # noqa: E402


def load_configs(overrides: list[str]):
    """Base YAMLs merged with ``robot.*``/``data.*`` dotlist overrides; ``seed=N`` picks the test-set seed."""
    base = OmegaConf.create({
        "robot": OmegaConf.load(REPO / "configs/robot/two_link.yaml"),
        "data": OmegaConf.load(REPO / "configs/data/paper.yaml"),
        "seed": 0,
    })
    for o in overrides:
        if o.split("=", 1)[0].split(".")[0] not in base:
            raise SystemExit(f"unknown override {o!r}: use robot.KEY=..., data.KEY=... or seed=N")
    OmegaConf.set_struct(base, True)  # typos in keys fail instead of silently adding a key
    try:
        cfg = OmegaConf.merge(base, OmegaConf.from_dotlist(overrides))
    except Exception as e:  # noqa: BLE001 - report the bad override, not a traceback
        raise SystemExit(f"bad override: {e}") from None
    OmegaConf.set_struct(cfg, False)
    return cfg.robot, cfg.data, int(cfg.seed)


def main(argv: list[str]) -> None:
    positional = [a for a in argv if "=" not in a]
    if len(positional) > 1:
        raise SystemExit(__doc__)
    stem = Path(positional[0]) if positional else REPO / "outputs/data/exemplar"
    robot_cfg, data_cfg, seed = load_configs([a for a in argv if "=" in a])
    arm = TwoLinkArm.from_config(robot_cfg)

    t0 = time.perf_counter()
    ex = D.build_exemplar_set(arm, data_cfg)
    t1 = time.perf_counter()
    tests = D.make_test_sets(arm, data_cfg, ex, seed)
    t2 = time.perf_counter()
    G = arm.gravity(torch.zeros(2, dtype=torch.float64))
    print(f"robot {OmegaConf.to_container(robot_cfg)}  G(θ=0) = ({G[0]:.3f}, {G[1]:.3f}) Nm")
    print(f"exemplar set: {len(ex)} of {ex.n_candidates} candidates ({t1 - t0:.3f} s); "
          f"test10: {len(tests.test10)}, heldout: {len(tests.heldout)} ({t2 - t1:.3f} s)")
    for name, k in zip(D.TARGET_NAMES, range(2)):
        print(f"  exemplar {name}: {ex.Y[:, k].min():.3f} .. {ex.Y[:, k].max():.3f} Nm")
    for mode in ("exemplar", "commanded"):
        s = D.Scaler.fit(ex, OmegaConf.merge(data_cfg, {"scaling": {"mode": mode}}))
        ys = s.transform_y(ex.Y)
        rng = ", ".join(f"{n} [{ys[:, k].min():.3f}, {ys[:, k].max():.3f}]" for k, n in enumerate(D.TARGET_NAMES))
        print(f"  scaling.mode={mode:9s} scaled exemplar targets: {rng}")
    paths = D.export(stem, ex, tests, robot_cfg, data_cfg)
    print(f"config_hash={D.config_hash(robot_cfg, data_cfg)}  seed={seed}")
    for p in paths.values():
        print(f"  wrote {p}")


if __name__ == "__main__":
    main(sys.argv[1:])
