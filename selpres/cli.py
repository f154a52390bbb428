"""What ``python train.py`` does around ``train``: output folder, skip/resume, errors, summary.

A job's folder is named by its overrides, so the same command finds the same folder: a finished job
is not redone (``overwrite=true`` forces it), a killed one resumes from its checkpoint, and re-running a
sweep fills in only the jobs that are missing or failed.
A config error in a single run prints one line and exits 2 with nothing left in ``outputs/``; in a sweep it
fails that job alone (its ``results.json`` says ``"status": "failed"``) and the sweep goes on.
"""

from __future__ import annotations

import json
import logging
import shutil
import sys
import traceback
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from selpres.errors import ConfigError
from selpres.storage import CHECKPOINT, RESULTS, WEIGHTS, write_json
from selpres.train import job_hash, summary_table, train

log = logging.getLogger("selpres")


def _finished(out: Path, cfg: DictConfig) -> dict | None:
    path = out / RESULTS
    if not path.exists():
        return None
    try:
        res = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    if res.get("status") in ("complete", "diverged") and res.get("config_hash") == job_hash(cfg):
        return res
    return None


def _objective(res: dict) -> float:
    m = res["summary"]["heldout_rms_nm_overall"]["mean"]
    return float("inf") if m is None else m


def _failed(out: Path, cfg: DictConfig, error: str, kind: str) -> None:
    """A failed job's results.json: enough for the report to list it in its place."""
    record = {
        "status": "failed", "error": error, "kind": kind, "schedule": {"name": cfg.schedule.name},
        "topology": cfg.topology.layers, "replicas": cfg.replicas,
        "seeds": [cfg.seed + r for r in range(cfg.replicas)],
    }
    write_json(out / RESULTS, record)


def run_job(cfg: DictConfig) -> float:
    """Hydra task function body; returns the mean held-out RMS (Nm) for sweepers such as Optuna."""
    hc = HydraConfig.get()
    out = Path(hc.runtime.output_dir)
    multirun = hc.mode == RunMode.MULTIRUN
    fresh = not any((out / f).exists() for f in (RESULTS, CHECKPOINT, WEIGHTS))
    try:
        if not cfg.overwrite and (res := _finished(out, cfg)) is not None:
            print(f"already done: {out / RESULTS} (overwrite=true to run it again)")
        else:
            if cfg.overwrite:  # a fresh start: not a resume of whatever an earlier run left behind
                (out / CHECKPOINT).unlink(missing_ok=True)
            res = train(cfg, out)
    except ConfigError as e:
        if multirun:
            log.error("config error: %s", e)
            _failed(out, cfg, str(e), "config")
            raise
        print(f"error: {e}", file=sys.stderr)
        if fresh:
            shutil.rmtree(out, ignore_errors=True)
        sys.exit(2)
    except Exception as e:  # a crash: keep the traceback in the job's log, mark the job failed
        log.error("job failed:\n%s", traceback.format_exc())
        _failed(out, cfg, repr(e), "exception")
        raise
    print(summary_table(res))
    print(f"results: {out / RESULTS}")
    return _objective(res)
