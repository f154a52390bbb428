"""Export the exemplar and test sets (npz + full-precision CSVs), composed exactly as training composes them.

    selpres-export [--out STEM] [--urdf PATH] [robot=NAME] [data=NAME] [robot.KEY=VALUE ...]
                   [data.KEY=VALUE ...]
    python -m selpres.run.export --help

The robot and data configs come from ``configs/train.yaml`` with the same schema and defaults as
``python train.py`` (``data.test_seed`` included), so ``selpres.data.export.load_exported(path, cfg.robot,
cfg.data)`` of a training config accepts the files it matches and refuses any other. The CSVs name
their columns (``q1..qN, dq1..dqN, ddq1..ddqN, tau1..tauN`` for a sampled arm, ``k_fx..k_mz`` for a
non-zero wrench; the paper's theta1, dtheta1, ... for its grid) and carry the arm (``# arm=`` its
canonical description). ``--urdf PATH`` also writes the arm as a URDF, so other tools (Pinocchio, MuJoCo,
``robot=urdf``) load exactly the dynamics selpres simulates. Also prints the scaled target ranges of both
scaling modes (why ``exemplar`` is the default).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import torch

from selpres.arms.sources import make_arm
from selpres.arms.two_link import TwoLinkArm
from selpres.arms.urdf import to_urdf
from selpres.data import export as E
from selpres.data.task import load_task
from selpres.errors import ConfigError
from selpres.run.checks import check_task
from selpres.run.config import CONFIG_DIR, compose_train
from selpres.run.specs import task_specs


def compose_data_config(overrides: list[str]):
    """(robot, data) specs of train.py's config with ``robot``/``data`` overrides, checked (not the topology)."""
    robot, data = task_specs(compose_train(CONFIG_DIR, overrides))
    check_task(robot, data)
    return robot, data


def export_data(stem: Path, robot_cfg, data_cfg, urdf: Path | None = None) -> dict[str, Path]:
    """Write the task's sets (and, with ``urdf``, the arm) and print what was written."""
    t0 = time.perf_counter()
    task = load_task(robot_cfg, data_cfg)
    t1 = time.perf_counter()
    ex, tests = task.exemplar, task.tests
    arm = make_arm(robot_cfg) if task.arm is not None else None
    if arm is not None:
        G = arm.gravity(torch.zeros(arm.dof, dtype=torch.float64))
        print(f"robot {arm.name} ({arm.dof} joints)  G(q=0) = ({', '.join(f'{g:.3f}' for g in G)}) Nm")
    info = task.info
    kept = f" of {info['candidates']:,} candidates" if "candidates" in info else ""
    print(
        f"exemplar set: {len(ex):,}{kept} ({info['source']}; {t1 - t0:.3f} s); "
        f"test10: {len(tests.test10)}, heldout: {len(tests.heldout):,}"
    )
    for k, name in enumerate(task.output_names):
        print(f"  exemplar {name}: {ex.Y[:, k].min():.3f} .. {ex.Y[:, k].max():.3f}")
    for mode in ("exemplar", "commanded"):
        try:
            s = task.fit_scaler(replace(data_cfg, scaling={**data_cfg.scaling, "mode": mode}))
        except ConfigError as e:
            print(f"  scaling.mode={mode:9s} not available: {e.allowed}")
            continue
        ys = s.transform_y(ex.Y)
        rng = ", ".join(f"{n} [{ys[:, k].min():.3f}, {ys[:, k].max():.3f}]" for k, n in enumerate(task.output_names))
        print(f"  scaling.mode={mode:9s} scaled exemplar targets: {rng}")
    paths = {}
    if urdf is not None:  # first: a refusal here leaves nothing written
        if arm is None:
            raise ConfigError("--urdf", str(urdf), "an arm to write: data=file has none")
        try:
            paths["urdf"] = to_urdf(arm.as_serial() if isinstance(arm, TwoLinkArm) else arm, urdf)
        except ValueError as e:
            raise ConfigError("--urdf", str(urdf), f"an arm URDF can name: {e}") from None
    paths.update(
        E.export(
            stem,
            ex,
            tests,
            robot_cfg,
            data_cfg,
            input_names=task.input_names,
            target_names=task.output_names,
            arm=task.arm,
            wrench=task.wrench,
        )
    )
    print(f"config_hash={E.config_hash(robot_cfg, data_cfg)}  (robot + data, test_seed={data_cfg.test_seed})")
    for p in paths.values():
        print(f"  wrote {p}")
    return paths


def default_stem(robot_cfg, data_cfg) -> Path:
    """outputs/data/<robot>_<data>: the arm (a file's name, else its name or source) and the data's kind, so
    exports of different tasks do not land on one name and no name repeats itself (``exemplar_exemplar.csv``)."""
    p = robot_cfg.params
    robot = Path(p["path"]).stem if isinstance(p.get("path"), str) else (p.get("name") or robot_cfg.target)
    return Path("outputs/data") / f"{robot}_{E.data_kind(data_cfg)}"


def _override(text: str) -> str:
    key = text.split("=", 1)[0]
    if "=" not in text or not (key in ("robot", "data") or key.startswith(("robot.", "data."))):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not allowed here: expected robot=NAME, data=NAME, robot.KEY=VALUE or data.KEY=VALUE"
        )
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="selpres-export",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__.split("\n\n", 2)[2],
    )
    ap.add_argument(
        "overrides",
        nargs="*",
        type=_override,
        metavar="KEY=VALUE",
        help="robot=NAME, data=NAME, robot.* or data.* overrides, as for train.py",
    )
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output stem: writes STEM.npz and STEM_{exemplar,test10,heldout}.csv "
        "(default: outputs/data/<robot>_<data>, e.g. outputs/data/two_link_grid)",
    )
    ap.add_argument(
        "--urdf",
        type=Path,
        default=None,
        metavar="PATH",
        help="also write the arm as a URDF file (load it with robot=urdf robot.path=PATH)",
    )
    args = ap.parse_args(argv)
    try:
        robot_cfg, data_cfg = compose_data_config(args.overrides)
    except Exception as e:  # a ConfigError, or Hydra's own message (unknown key, wrong type): no traceback
        ap.exit(2, f"error: {e}\n")
    try:
        export_data(args.out or default_stem(robot_cfg, data_cfg), robot_cfg, data_cfg, args.urdf)
    except ConfigError as e:  # raised while making the data, before anything is written
        ap.exit(2, f"error: {e}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
