"""``selpres-train`` (and a checkout's ``python train.py``, a shim over this): Hydra's main on the package's configs.

The config path is :data:`selpres.run.config.CONFIG_DIR`, an absolute path inside the package, so the same command
composes the same config from a checkout, an editable install or a wheel in site-packages, run from any folder;
a job's folder is relative to the folder it runs in (``outputs/runs/<overrides>/``, ``hydra.run.dir`` moves it).
Only Hydra, omegaconf and the schema load before Hydra parses the command line: torch and the loop
(:mod:`selpres.run.cli`) load for a job, not for ``--help`` or ``--cfg``.
"""

from __future__ import annotations

import gc
import sys

try:  # a Ctrl-C while the imports load: one line, exit 130 (nothing is written before Hydra starts)
    import hydra
    from omegaconf import DictConfig

    from selpres.run.config import CONFIG_DIR  # also registers the typed schema and resolvers before Hydra composes
    from selpres.run.guard import guarded
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)


@hydra.main(version_base="1.3", config_path=str(CONFIG_DIR), config_name="train")
def train_job(cfg: DictConfig) -> float:
    """Hydra's task function: one job (or one job of a sweep); the mean held-out RMS for sweepers such as Optuna."""
    # numpy before torch: torch's C start-up imports numpy itself, and a Ctrl-C landing in that import is cleared
    # there ("Failed to initialize NumPy"): the job ran on (exit 0) or failed on a half-imported numpy (exit 1)
    import numpy  # noqa: F401

    from selpres.run.cli import run_job  # torch and the loop only for a job, not for --help or --cfg

    return run_job(cfg)


def main() -> None:
    """The console script: the job inside the guard (lock, Ctrl-C), then the interpreter's exit made cheap."""
    try:
        guarded(train_job)
    finally:
        # Everything is written and closed by now; what remains is the interpreter's exit, whose cyclic-garbage
        # passes walk every object torch and Hydra made (0.3-0.5 s of a 2.5 s default run, measured with
        # `python -m selpres_bench.startup`). Frozen objects are skipped by those passes; atexit handlers
        # (logging's flush, weakref finalizers) still run.
        gc.freeze()


if __name__ == "__main__":
    main()
