"""What ``python train.py`` does around ``train``: output folder, skip/resume, errors, what is printed.

A job's folder is named by its overrides, so the same command finds the same folder: a finished job
is not redone (``overwrite=true`` forces it), a killed one resumes from its checkpoint, and re-running a
sweep fills in only the jobs that are missing or failed.
A config error in a single run prints one line and exits 2, and the run removes only what it created
(:class:`selpres.run.guard.OutputGuard` remembers what the folder held before Hydra wrote into it); in a
sweep it fails that job alone (its ``results.json`` says ``"status": "failed"``) and the sweep goes on.

One process writes a job folder at a time (:mod:`selpres.run.lock`): a single run takes the lock before Hydra
creates or writes anything there, and a second run on a folder in use exits 2 naming the holder's PID; in a
sweep the busy job is skipped (one line) and the others run (Hydra rewrites a sweep job's ``.hydra/`` before
any callback can run: the skipped job puts back the holder's copy, which the holder keeps in the lock file).
Workers of a sweep whose process is gone stop at the next epoch with their checkpoint kept
(:mod:`selpres.run.orphan`). A write that fails (disk full, a read-only folder) prints one line naming the
path; what was saved before stays.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
import sys
import traceback
from pathlib import Path
from typing import NoReturn

from hydra.core.hydra_config import HydraConfig
from hydra.errors import CompactHydraException
from hydra.types import RunMode
from omegaconf import DictConfig

from selpres.errors import ConfigError
from selpres.run import guard, lock, optimizer, orphan, progress, stop
from selpres.run.checkpoint import Checkpoints
from selpres.run.problem import Problem, engine_kind, kind_of
from selpres.run.results import job_hash
from selpres.run.train import train
from selpres.storage import RESULTS, remove_stale_temps, write_json

log = logging.getLogger("selpres")


class SweepJobError(CompactHydraException):
    """A sweep's job that failed for a reason its one line says (a config error, a busy folder): Hydra prints
    that line, not a traceback, when the sweep ends (exit 1); the other jobs ran."""


# ---------------------------------------------------------------------------------------- the job
def _finished(out: Path, cfg: DictConfig) -> dict | None:
    """The finished results of this job, if any: its config (job_hash) and the engines that ran it as this config
    would run now (a routing change, as issue 22's move of paper-regime pruning jobs off the mini-batch engine,
    makes a finished result another update's)."""
    path = out / RESULTS
    if not path.exists():
        return None
    try:
        res = json.loads(path.read_bytes())
    except (OSError, ValueError):  # unreadable, not UTF-8, not JSON: not a finished job (it is redone)
        return None
    if not isinstance(res, dict):
        return None
    if res.get("status") in ("complete", "diverged") and res.get("config_hash") == job_hash(cfg):
        ran, now = kind_of(res.get("engine")), engine_kind(cfg)
        try:  # what the command line reads of a finished job (a hand-edited or cut file: the job is redone)
            summary_table(res), _objective(res)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as e:
            log.warning("%s lacks what a finished job holds (%s: %s): running it again", path, type(e).__name__, e)
            return None
        if ran == now:
            return res
        log.warning("%s ran on the %s engines; this config now runs on the %s ones: running it again", path, ran, now)
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
        # the seeds listed only when few: a refused replicas=1000000000 must not build 10^9 of them
        "seeds": [cfg.seed + r for r in range(cfg.replicas)] if 0 < cfg.replicas <= 10_000 else None,
        "seed_range": [cfg.seed, cfg.seed + cfg.replicas - 1],
    }
    write_json(out / RESULTS, record)


def _leftovers(out: Path, cfg: DictConfig) -> None:
    """A kill during the final writes of a finished job (results.json is written before the checkpoint is
    removed) leaves this job's checkpoint files next to its results: removed on the re-run that finds it done."""
    chash = job_hash(cfg)
    ckpts = Checkpoints(out, chash)
    if ckpts.leftover():
        ckpts.discard()
        log.info("removed the checkpoint a kill left in the finished job %s", out)


def run_job(cfg: DictConfig) -> float:
    """Hydra task function body; returns the mean held-out RMS (Nm) for sweepers such as Optuna."""
    guard.job_started()
    with stop.handling():  # a sweep's job runs in a launcher's worker (loky, submitit), where train.py never ran
        return _job(cfg)


def _job(cfg: DictConfig) -> float:
    hc = HydraConfig.get()
    out = Path(hc.runtime.output_dir)
    multirun = hc.mode == RunMode.MULTIRUN
    optimizer.composed_from(hc.runtime.choices.get("optim"))  # what a _target_ given over it may leave behind
    try:
        _check_name(hc, multirun)
    except ConfigError as e:  # before the job touches its folder: remove only what this run created
        print(f"error: {e}", file=sys.stderr)
        guard.undo(out)
        sys.exit(2)
    if multirun and orphan.watch() is not None and orphan.gone():
        _orphaned(out, "before it started")
    try:
        held = lock.hold(out)  # a single run took it in OutputGuard.on_run_start; a sweep's job takes it here
    except lock.FolderBusy as e:  # not logged: the log file is the holder's
        if multirun:
            _restore_record(out, e.record)
            print(f"skipped (busy): {e}", file=sys.stderr)
            raise SweepJobError(f"skipped (busy): {e}") from None
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    hydra = out / ".hydra"
    try:
        held.remember({p.name: p.read_bytes() for p in hydra.iterdir() if p.is_file()} if hydra.is_dir() else {})
    except OSError:
        pass
    try:
        return _run_locked(cfg, out, multirun)
    finally:
        lock.release(out)


def _restore_record(out: Path, record: dict[str, bytes]) -> None:
    """Put back the holder's ``.hydra/`` files that Hydra rewrote for this busy sweep job before any selpres
    code ran (the holder left them in the lock file); nothing else of the folder was touched."""
    for name, data in record.items():
        path = out / ".hydra" / name
        try:
            if path.read_bytes() != data:
                path.write_bytes(data)
        except OSError:
            pass


def _orphaned(out: Path, where: str) -> None:
    """This sweep worker's sweep process is gone: stop the process here (the checkpoint, if any, kept)."""
    log.warning(
        "the sweep that launched this job is gone (PID %s): stopped %s; run the sweep again to resume %s",
        os.environ.get(orphan.ENV, "?").rsplit(":", 2)[1],
        where,
        out,
    )
    logging.shutdown()
    lock.release(out)
    os._exit(3)


def _run_locked(cfg: DictConfig, out: Path, multirun: bool) -> float:
    remove_stale_temps(out)
    try:
        res = None if cfg.overwrite else _finished(out, cfg)
        if res is not None:
            log.info("already done: %s (overwrite=true to run it again)", out / RESULTS)
            _leftovers(out, cfg)
        else:
            line = progress.EpochLine.for_run(multirun) if cfg.logging.progress else None  # a terminal's line
            res = train(cfg, out, on_stage_end=print_stage if cfg.logging.progress else None, on_epoch=line)
    except orphan.SweepGone as e:
        _orphaned(out, str(e))
    except ConfigError as e:
        if multirun:
            log.error("config error: %s", e)
            _failed(out, cfg, str(e), "config")
            raise SweepJobError(f"{out}: config error: {e}") from None
        print(f"error: {e}", file=sys.stderr)
        guard.undo(out)
        sys.exit(2)
    except OSError as e:  # disk full, a read-only or immutable folder: the checkpoint already written stays
        kept = "the last checkpoint is kept" if Checkpoints.present(out) else "no checkpoint was written yet"
        line = (
            f"cannot write {e.filename or out}: {e.strerror or e} (errno {e.errno}); {kept}: "
            "run the same command again once it can be written"
        )
        _to_log_file(f"job failed: {line}\n{traceback.format_exc()}")  # the traceback in train.log only
        try:
            _failed(out, cfg, line, "exception")
        except OSError:  # the disk that is full cannot take this record either
            pass
        if multirun:
            print(line, file=sys.stderr)
            raise SweepJobError(f"{out}: {line}") from None
        print(f"error: {line}", file=sys.stderr)
        sys.exit(2)
    except stop.Terminated as e:  # SIGTERM / SIGUSR1 (selpres.run.stop): the loop wrote a checkpoint first
        resumable = Checkpoints.present(out)
        if resumable:
            how = "run the same command to resume"
        else:  # a sweep's job keeps its folder (Hydra's record, its log), as for any failed job
            how = "no checkpoint yet: the same command starts it again" if multirun else "nothing of this run was kept"
        line = f"{out}: {e}; {how}"
        if multirun and os.environ.get("SUBMITIT_EXECUTOR") != "slurm":
            _terminated_in_sweep(out, line)
        print(f"{'' if multirun else 'error: '}{line}", file=sys.stderr)
        logging.shutdown()
        if not resumable and not multirun:
            guard.undo(out)
        lock.release(out)
        sys.exit(stop.STATUS)
    except KeyboardInterrupt:
        if multirun:
            raise
        resumable = Checkpoints.present(out)
        print("interrupted" + ("; run the same command to resume" if resumable else ""), file=sys.stderr)
        if not resumable:  # interrupted before anything worth keeping
            guard.undo(out)
        sys.exit(130)
    except Exception as e:  # a crash: keep the traceback in the job's log, mark the job failed
        if isinstance(e, MemoryError) or _torch_out_of_memory(e):
            _out_of_memory(out, e, multirun)
        log.error("job failed:\n%s", traceback.format_exc())
        _failed(out, cfg, repr(e), "exception")
        raise
    log.info("%s\nresults: %s", summary_table(res), out / RESULTS)
    return _objective(res)


def _terminated_in_sweep(out: Path, line: str) -> NoReturn:
    """A signal stopped a sweep's job in a worker that is not SLURM's: the job fails in one line (Hydra prints it
    when the sweep ends, exit 1; the sweep's other jobs run) and the same sweep command resumes it. Under SLURM
    the job's process exits 143 instead (above): submitit writes no result, so the sweep keeps waiting while SLURM
    requeues the job (preemption, ``scontrol requeue``), and the requeued job resumes from the checkpoint; a
    result written here would make the sweep count the job as done (submitit: done once a result file exists)."""
    log.warning("%s", line)  # to the job's log and the sweep's console
    lock.release(out)
    raise SweepJobError(line) from None


def _torch_out_of_memory(e: BaseException) -> bool:
    """torch's failed allocation: a RuntimeError ("DefaultCPUAllocator: can't allocate memory"), not MemoryError."""
    return isinstance(e, RuntimeError) and ("can't allocate memory" in str(e) or "out of memory" in str(e).lower())


def _out_of_memory(out: Path, e: BaseException, multirun: bool) -> NoReturn:
    """An allocation failed past the estimate (selpres.run.estimate: other processes took the memory, a cap it could
    not see, or it erred): one line, exit 2; the last checkpoint is kept, else this run's files are removed."""
    from selpres.run.estimate import available_memory, gb

    limit, source = available_memory()
    asked = re.search(r"allocate (\d+) bytes", str(e))
    what = f"{gb(int(asked.group(1)))} at once" if asked else type(e).__name__
    kept = Checkpoints.present(out)
    line = (
        f"out of memory: an allocation of {what} failed with {gb(limit)} available ({source}); lower replicas or "
        "free memory; " + ("the last checkpoint is kept: run the same command again to resume" if kept else
                           "nothing of this run was kept")
    )  # fmt: skip
    _to_log_file(f"job failed: {line}\n{traceback.format_exc()}")  # the traceback in train.log only
    if multirun:
        print(line, file=sys.stderr)
        raise SweepJobError(f"{out}: {line}") from None
    print(f"error: {line}", file=sys.stderr)
    if not kept:
        guard.undo(out)
    sys.exit(2)


def _check_name(hc, multirun: bool) -> None:
    """``name=`` names a sweep's folder; a single run's folder is named by its overrides, so ``name=`` there would be
    silently ignored: refuse it."""
    given = [o.split("=", 1)[1] for o in hc.overrides.task if o.split("=", 1)[0] == "name"]
    if given and not multirun:
        raise ConfigError(
            "name",
            given[0],
            "only with -m (a sweep's folder outputs/sweeps/<name>/); a single run's folder is named by its "
            "overrides (or hydra.run.dir=...)",
        )


def _to_log_file(text: str) -> None:
    """``text`` into the job's log file (Hydra's file handler), not onto the console."""
    record = logging.LogRecord("selpres", logging.ERROR, __file__, 0, text, None, None)
    for handler in logging.getLogger().handlers:
        if isinstance(handler, logging.FileHandler):
            try:
                handler.handle(record)
            except OSError:
                pass


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
