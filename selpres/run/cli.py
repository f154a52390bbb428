"""What ``python train.py`` does around ``train``: output folder, skip/resume, errors, what is printed.

A job's folder is named by its overrides, so the same command finds the same folder: a finished job
is not redone (``overwrite=true`` forces it), a killed one resumes from its checkpoint, and re-running a
sweep fills in only the jobs that are missing or failed.
A config error in a single run prints one line and exits 2, and the run removes only what it created
(:class:`OutputGuard` remembers what the folder held before Hydra wrote into it); in a sweep it fails that
job alone (its ``results.json`` says ``"status": "failed"``) and the sweep goes on.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from selpres.errors import ConfigError
from selpres.run.checkpoint import Checkpoints
from selpres.run.results import job_hash
from selpres.run.train import Problem, train
from selpres.storage import RESULTS, write_json

log = logging.getLogger("selpres")


# ------------------------------------------------------------------ what a run may remove on refusal
@dataclass
class Before:
    """A run folder as it was before Hydra wrote into it."""

    created: Path | None  # the topmost folder this run creates (None: the run folder existed)
    entries: set[str] = field(default_factory=set)  # names in the run folder
    hydra_files: dict[str, bytes] = field(default_factory=dict)  # .hydra/* contents Hydra will overwrite
    log_size: int | None = None  # train.log's size (Hydra appends to it)

    @classmethod
    def look(cls, folder: Path) -> Before:
        if not folder.exists():
            created = folder
            while not created.parent.exists():
                created = created.parent
            return cls(created)
        hydra = folder / ".hydra"
        files = {p.name: p.read_bytes() for p in hydra.iterdir() if p.is_file()} if hydra.is_dir() else {}
        log_file = folder / "train.log"
        return cls(
            None, {p.name for p in folder.iterdir()}, files, log_file.stat().st_size if log_file.exists() else None
        )

    def undo(self, folder: Path) -> None:
        """Remove what the run created and restore what Hydra overwrote; never touch anything else."""
        if self.created is not None:
            shutil.rmtree(self.created, ignore_errors=True)
            return
        for entry in folder.iterdir():
            if entry.name not in self.entries:
                shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
        for name, data in self.hydra_files.items():
            (folder / ".hydra" / name).write_bytes(data)
        if self.log_size is not None and (folder / "train.log").exists():
            os.truncate(folder / "train.log", self.log_size)


_BEFORE: dict[Path, Before] = {}


class OutputGuard(Callback):
    """Hydra callback (configs/train.yaml): looks at the run folder before Hydra creates or writes into it."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        HydraConfig.instance().set_config(config)  # resolves ${hydra:job.override_dirname} as run_job will
        folder = Path(str(OmegaConf.select(config, "hydra.run.dir"))).absolute()
        _BEFORE[folder] = Before.look(folder)


def _undo(out: Path) -> None:
    before = _BEFORE.get(out.absolute())
    if before is not None:  # unknown (train.py run without the callback): remove nothing
        before.undo(out)


# ---------------------------------------------------------------------------------------- the job
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
        "status": "failed",
        "error": error,
        "kind": kind,
        "schedule": {"name": cfg.schedule.name},
        "topology": cfg.topology.layers,
        "replicas": cfg.replicas,
        "seeds": [cfg.seed + r for r in range(cfg.replicas)],
    }
    write_json(out / RESULTS, record)


def run_job(cfg: DictConfig) -> float:
    """Hydra task function body; returns the mean held-out RMS (Nm) for sweepers such as Optuna."""
    hc = HydraConfig.get()
    out = Path(hc.runtime.output_dir)
    multirun = hc.mode == RunMode.MULTIRUN
    try:
        res = None if cfg.overwrite else _finished(out, cfg)
        if res is not None:
            log.info("already done: %s (overwrite=true to run it again)", out / RESULTS)
        else:
            res = train(cfg, out, on_stage_end=print_stage if cfg.logging.progress else None)
    except ConfigError as e:
        if multirun:
            log.error("config error: %s", e)
            _failed(out, cfg, str(e), "config")
            raise
        print(f"error: {e}", file=sys.stderr)
        _undo(out)
        sys.exit(2)
    except KeyboardInterrupt:
        if multirun:
            raise
        resumable = Checkpoints.present(out)
        print("interrupted" + ("; run the same command to resume" if resumable else ""), file=sys.stderr)
        if not resumable:  # interrupted before anything worth keeping
            _undo(out)
        sys.exit(130)
    except Exception as e:  # a crash: keep the traceback in the job's log, mark the job failed
        log.error("job failed:\n%s", traceback.format_exc())
        _failed(out, cfg, repr(e), "exception")
        raise
    log.info("%s\nresults: %s", summary_table(res), out / RESULTS)
    return _objective(res)


# ------------------------------------------------------------------------------ what gets printed
def _mean(vals) -> float:
    f = [v for v in vals if v is not None]
    return sum(f) / len(f) if f else math.nan


def print_stage(rec: dict, prob: Problem) -> None:
    """One line at the end of each stage: size, epoch, cost so far and the errors (mean over replicas)."""
    R = len(prob.seeds)
    held = f"  held-out RMS {_mean(rec['heldout_rms_nm']):.4f} Nm" if rec["heldout_rms_nm"] else ""
    log.info(
        f"stage {rec['stage'] + 1}/{len(prob.schedule.stages)}  n_i={rec['size']:5d}  epoch {rec['epoch'] + 1:4d}  "
        f"presentations {rec['presentations']:7d}  train MSE {_mean(rec['train_mse']):.3e}  "
        f"test-10 RMS {_mean(rec['test10_rms_nm']):.4f} Nm{held}" + (f"  (mean of {R} replicas)" if R > 1 else "")
    )


def summary_table(results: dict) -> str:
    """The short table printed at the end of a job."""
    s, sch = results["summary"], results["schedule"]

    def fmt(key):
        m = s[key]
        if m["mean"] is None:
            return "n/a"
        return f"{m['mean']:.4f}" + (f" ± {m['std']:.4f}" if m["std"] is not None else "")

    engine, fallback = results["engine"], results.get("engine_fallback")
    if results.get("engine_requested", engine) != engine:
        engine += f" (requested {results['engine_requested']}" + (f"; fell back: {fallback}" if fallback else "") + ")"
    wall = results["wall_seconds"]
    rows = [
        ("schedule", f"{sch['name']} (p={sch['p']}, sizes {sch['sizes']}, epochs {sch['epochs']})"),
        ("topology", results["topology"]),
        (
            "replicas",
            f"{results['replicas']} (seeds {results['seeds'][0]}..{results['seeds'][-1]}), "
            f"{results['diverged_replicas']} diverged",
        ),
        (
            "cost T/t",
            f"{sch['presentations']:,} presentations  (T_con/t at equal epochs "
            f"{sch['conventional_presentations']:,}; ratio {sch['cost_ratio']:.3f})"
            + (
                f" + {results['selection_presentations']:,} charged for choosing A_i"
                if results.get("selection_presentations")
                else ""
            ),
        ),
        ("engine", engine),
        ("wall time", f"{wall['total']:.2f} s total, {wall['train']:.2f} s in updates"),
        ("test-10 RMS", f"{fmt('test10_rms_nm_overall')} Nm   {fmt('test10_rms_scaled_overall')} scaled"),
        ("held-out RMS", f"{fmt('heldout_rms_nm_overall')} Nm   {fmt('heldout_rms_scaled_overall')} scaled"),
    ]
    if "heldout_rms_nmse_overall" in s and results.get("floor"):  # selpres.run.floor
        base = results["floor"]["heldout"]["nm"]["overall"]
        rows.append(("held-out nMSE", f"{fmt('heldout_rms_nmse_overall')}   (predicting the mean: {base:.4f} Nm)"))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)
