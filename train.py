"""Train the paper's network: ``python train.py schedule=selective topology=6-13-2`` (see README)."""

import gc
import sys

try:  # a Ctrl-C while the imports load: one line, exit 130 (nothing is written before Hydra starts)
    import hydra
    from omegaconf import DictConfig

    import selpres.run.config  # noqa: F401  (registers the typed schema and resolvers before Hydra composes)
    from selpres.run.guard import guarded
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)


@hydra.main(version_base="1.3", config_path="selpres/configs", config_name="train")
def main(cfg: DictConfig) -> float:
    from selpres.run.cli import run_job  # torch and the loop only for a job, not for --help or --cfg

    return run_job(cfg)


if __name__ == "__main__":
    try:
        guarded(main)
    finally:
        # Everything is written and closed by now; what remains is the interpreter's exit, whose cyclic-garbage
        # passes walk every object torch and Hydra made (0.3-0.5 s of a 2.5 s default run, measured with
        # `python -m selpres.bench.startup`). Frozen objects are skipped by those passes; atexit handlers
        # (logging's flush, weakref finalizers) still run.
        gc.freeze()
