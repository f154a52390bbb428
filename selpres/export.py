"""Export the exemplar and test sets (npz + full-precision CSVs), composed exactly as training composes them.

    selpres-export [--out STEM] [robot.KEY=VALUE ...] [data.KEY=VALUE ...]
    python -m selpres.export --help

The robot and data configs come from ``configs/train.yaml`` with the same schema and defaults as
``python train.py`` (``data.test_seed`` included), so ``selpres.data.load_exported(path, cfg.robot,
cfg.data)`` of a training config accepts the files it matches and refuses any other. Also prints the
scaled target ranges of both scaling modes (why ``exemplar`` is the default).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf

from selpres import data as D
from selpres.checks import validate
from selpres.config import CONFIG_DIR, to_container
from selpres.errors import ConfigError
from selpres.robot import TwoLinkArm


def compose_data_config(overrides: list[str]):
    """(robot, data) of train.py's config with ``robot.*`` / ``data.*`` overrides, validated."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose("train", overrides=overrides)
    validate(cfg)
    return OmegaConf.create(to_container(cfg.robot)), OmegaConf.create(to_container(cfg.data))


def export_data(stem: Path, robot_cfg, data_cfg) -> dict[str, Path]:
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


def _override(text: str) -> str:
    if "=" not in text or not text.startswith(("robot.", "data.")):
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed here: expected robot.KEY=VALUE or data.KEY=VALUE")
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="selpres-export", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=__doc__.split("\n\n", 2)[2])
    ap.add_argument("overrides", nargs="*", type=_override, metavar="KEY=VALUE",
                    help="robot.* or data.* overrides, as for train.py")
    ap.add_argument("--out", type=Path, default=Path("outputs/data/exemplar"),
                    help="output stem: writes STEM.npz and STEM_{exemplar,test10,heldout}.csv "
                         "(default: %(default)s)")
    args = ap.parse_args(argv)
    try:
        robot_cfg, data_cfg = compose_data_config(args.overrides)
    except ConfigError as e:
        ap.exit(2, f"error: {e}\n")
    except Exception as e:  # noqa: BLE001  Hydra's own message (unknown key, wrong type), without a traceback
        ap.exit(2, f"error: {e}\n")
    export_data(args.out, robot_cfg, data_cfg)
    return 0


if __name__ == "__main__":
    sys.exit(main())
