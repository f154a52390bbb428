"""Build the exemplar set and test sets from the configs and export them (npz + full-precision CSVs).

    python scripts/export_data.py [out_stem] [robot.KEY=VALUE ...] [data.KEY=VALUE ...]

The robot and data configs are composed exactly as ``train.py`` composes them (same schema, same
defaults, ``data.test_seed`` included), so ``selpres.data.load_exported(path, cfg.robot, cfg.data)`` of a
training config accepts the files it matches and refuses any other. Default out_stem:
outputs/data/exemplar. Also prints the scaled target ranges of both scaling modes (why 'exemplar' is
the default).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from selpres import data as D  # noqa: E402
from selpres.config import to_container, validate  # noqa: E402
from selpres.errors import ConfigError  # noqa: E402
from selpres.robot import TwoLinkArm  # noqa: E402


def compose_data_config(overrides: list[str]):
    """(robot, data) of train.py's config with ``robot.*`` / ``data.*`` overrides, validated."""
    bad = [o for o in overrides if not o.startswith(("robot.", "data."))]
    if bad:
        raise SystemExit(f"error: override {bad[0]!r} is not allowed here: use robot.KEY=VALUE or data.KEY=VALUE")
    try:
        with initialize_config_dir(config_dir=str(REPO / "configs"), version_base="1.3"):
            cfg = compose("train", overrides=overrides)
        validate(cfg)
    except ConfigError as e:
        raise SystemExit(f"error: {e}") from None
    except Exception as e:  # noqa: BLE001  Hydra's own message (unknown key, wrong type), without a traceback
        raise SystemExit(f"error: {e}") from None
    return OmegaConf.create(to_container(cfg.robot)), OmegaConf.create(to_container(cfg.data))


def export_data(stem: Path, overrides: list[str]) -> dict[str, Path]:
    robot_cfg, data_cfg = compose_data_config(overrides)
    arm = TwoLinkArm.from_config(robot_cfg)
    t0 = time.perf_counter()
    ex = D.build_exemplar_set(arm, data_cfg)
    t1 = time.perf_counter()
    tests = D.make_test_sets(arm, data_cfg, ex, data_cfg.test_seed)
    t2 = time.perf_counter()
    G = arm.gravity(torch.zeros(2, dtype=torch.float64))
    print(f"robot {OmegaConf.to_container(robot_cfg)}  G(θ=0) = ({G[0]:.3f}, {G[1]:.3f}) Nm")
    print(f"exemplar set: {len(ex)} of {ex.n_candidates} candidates ({t1 - t0:.3f} s); "
          f"test10: {len(tests.test10)}, heldout: {len(tests.heldout)} ({t2 - t1:.3f} s)")
    for k, name in enumerate(D.TARGET_NAMES):
        print(f"  exemplar {name}: {ex.Y[:, k].min():.3f} .. {ex.Y[:, k].max():.3f} Nm")
    for mode in ("exemplar", "commanded"):
        s = D.Scaler.fit(ex, OmegaConf.merge(data_cfg, {"scaling": {"mode": mode}}))
        ys = s.transform_y(ex.Y)
        rng = ", ".join(f"{n} [{ys[:, k].min():.3f}, {ys[:, k].max():.3f}]" for k, n in enumerate(D.TARGET_NAMES))
        print(f"  scaling.mode={mode:9s} scaled exemplar targets: {rng}")
    paths = D.export(stem, ex, tests, robot_cfg, data_cfg)
    print(f"config_hash={D.config_hash(robot_cfg, data_cfg)}  (robot + data, test_seed={data_cfg.test_seed})")
    for p in paths.values():
        print(f"  wrote {p}")
    return paths


def main(argv: list[str]) -> None:
    positional = [a for a in argv if "=" not in a]
    if len(positional) > 1:
        raise SystemExit(__doc__)
    export_data(Path(positional[0]) if positional else REPO / "outputs/data/exemplar", [a for a in argv if "=" in a])


if __name__ == "__main__":
    main(sys.argv[1:])
