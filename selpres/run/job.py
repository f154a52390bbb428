"""A job folder's life, in one place: its lock, start or resume, interruption, and the outcome it ends in.

Hydra calls :func:`run` for every job of ``python train.py`` (:mod:`selpres.run.main`), and :func:`run` reads top to
bottom: it holds the job's folder (:func:`selpres.run.lock.holding`: taken here, before anything is written there,
and released here); a finished job of this config is skipped, one of another config refused (``overwrite=true``
replaces it); Hydra's record (``.hydra/``) is written; :func:`selpres.run.train.train` trains, resuming from this
job's checkpoint if there is one; and the job ends as one row of :data:`selpres.run.outcomes.OUTCOMES` (its exit
status, its one line, what ``results.json`` then says).

A single run that is refused or stopped before it has anything worth keeping leaves its folder as it found it;
nothing this run did not create is removed (:class:`selpres.run.folder.Before`). A signal is answered wherever it
lands (:mod:`selpres.run.stop`): in the loop with a checkpoint at the end of the epoch under way; before it, with
nothing kept. In a sweep a job that does not finish fails alone, named by its line (said when the sweep ends, which
exits 1; the others ran), except that a signal to the sweep's own process stops the sweep.
"""

from __future__ import annotations

import logging
import os
import re
import signal
import sys
import traceback
from pathlib import Path

from hydra.errors import CompactHydraException
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from selpres.errors import ConfigError
from selpres.run import cli, folder, lock, orphan, stop
from selpres.run.outcomes import (
    BUSY,
    DONE,
    FAILED,
    INTERRUPTED,
    ORPHANED,
    OUT_OF_MEMORY,
    PROTECTED,
    REFUSED,
    RESUMED,
    SKIPPED,
    TERMINATED,
    WRITE_FAILED,
    Ending,
)
from selpres.storage import RESULTS, remove_stale_temps

log = logging.getLogger("selpres")
COMMAND = "SELPRES_COMMAND"  # the command as typed (set by selpres.run.main; a sweep's workers inherit it)
FULL_ERROR = "SELPRES_FULL_ERROR"  # set by selpres.run.main when the user asked for HYDRA_FULL_ERROR=1
_CREATED: dict[Path, Path | None] = {}  # a single run's folder -> what of its path Hydra was about to create
_STARTED: list[Ending | None] = []  # the jobs run() began in this process (None while one is under way)
_UNFINISHED: list[str] = []  # the lines of this process's sweep jobs that did not finish, said when the sweep ends


def new_command() -> None:
    """Forget the jobs of an earlier command in this process (a test's, or a notebook's)."""
    _CREATED.clear(), _STARTED.clear(), _UNFINISHED.clear()


def unfinished() -> list[str]:
    """The lines of the sweep jobs this process ran that did not finish (the basic launcher's), in order."""
    return list(_UNFINISHED)


class SweepJobError(CompactHydraException):
    """A sweep's job that did not finish, for the reason its one line says: Hydra prints that line, not a
    traceback, when the sweep ends (exit 1); the other jobs ran."""


class FolderNote(Callback):
    """Hydra callback (``configs/train.yaml``): what of a single run's folder path does not exist before Hydra
    makes it (so a refusal removes only that), and, in a sweep, the sweep's process for its workers to watch
    (:mod:`selpres.run.orphan`)."""

    def on_run_start(self, config: DictConfig, **kwargs) -> None:
        from hydra.core.hydra_config import HydraConfig

        HydraConfig.instance().set_config(config)  # resolves ${hydra:job.override_dirname} as the job will
        at = Path(os.path.abspath(str(OmegaConf.select(config, "hydra.run.dir"))))
        _CREATED[at] = folder.Before.missing(at)

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        orphan.record_sweep_parent()


# ----------------------------------------------------------------------------------------------- the job
def run(cfg: DictConfig, out: Path | None = None) -> float:
    """Hydra's task function: one job's life in its folder, read top to bottom; returns the mean held-out RMS (Nm)
    for sweepers. ``out``: a folder a caller without Hydra gives (a single run; no Hydra record is written)."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    hc = HydraConfig.get() if out is None else None
    out = Path(hc.runtime.output_dir) if hc is not None else Path(out)
    sweep = hc is not None and hc.mode == RunMode.MULTIRUN
    created, finished = _CREATED.pop(out, None), None
    _STARTED.append(None)
    with stop.handling():
        try:
            stop.check("before the job started")  # a signal whose raise Hydra's composition lost
            # numpy before torch: torch's C start-up imports numpy itself, and a Ctrl-C there is cleared and leaves
            # torch without numpy (the stop is still recorded and answered, but the job must not crash first)
            import numpy  # noqa: F401

            with lock.holding(out):  # the one place: taken before anything is written here, released at the end
                before = folder.Before.look(out, created)
                stop.phase("during set-up")
                try:
                    from selpres.run import optimizer, progress
                    from selpres.run.train import train  # torch: seconds, in which a Ctrl-C is this job's to answer

                    optimizer.composed_from(hc.runtime.choices.get("optim") if hc else None)  # what a _target_ leaves
                    _check_name(hc, sweep)
                    folder.check_space(out)
                    if sweep and orphan.watch() is not None and orphan.gone():
                        raise orphan.SweepGone("before it started")
                    found = None if cfg.overwrite else folder.finished(out, cfg)
                    if found is not None and found[1]:  # refused before any work: the finished job stays as it is
                        ending = Ending(PROTECTED, {"folder": out, "differences": found[1]})
                    elif found is not None:
                        res = found[0]
                        remove_stale_temps(out)  # what a kill left of atomic writes (never under the final names)
                        folder.leftovers(out, cfg)  # and of a finished job's last writes
                        ending = finished = Ending(SKIPPED, {"results": out / RESULTS}, folder.objective(res))
                    else:
                        remove_stale_temps(out)  # what a kill left of atomic writes (never under the final names)
                        folder.open_log(out)  # the log the job reports into, there from its start
                        if hc is not None:
                            with stop.deferred():
                                folder.write_record(out, cfg, HydraConfig.instance().cfg, hc.overrides.task)
                        stop.check("during set-up")
                        shown = cfg.logging.progress  # a stage's line, and on a terminal the epoch's line (progress)
                        line = progress.EpochLine.for_run(sweep) if shown else None
                        res = train(cfg, out, on_stage_end=cli.print_stage if shown else None, on_epoch=line)
                        epoch = res.get("resumed_from_epoch")
                        outcome, fields = (DONE, {}) if epoch is None else (RESUMED, {"epoch": epoch})
                        fields["results"] = out / RESULTS
                        ending = finished = Ending(outcome, fields, folder.objective(res))
                    if finished is not None:
                        log.info("%s\n%s", cli.summary_table(res), ending.line)
                    stop.check("as the job ended")
                except BaseException as e:  # every way out is one Ending; its clean-up is not cut by a second signal
                    with stop.deferred():
                        ending = _ending(e, cfg, out, before, sweep, finished)
        except lock.FolderBusy as e:  # the folder is its holder's: nothing touched, nothing logged into it
            holder = f"process {e.pid}" if e.pid else "another process"
            ending = Ending(BUSY, {"folder": out, "holder": holder})
        except OSError as e:  # the lock file cannot be written (a full disk, a read-only folder)
            folder.remove_empty(out, created)
            ending = Ending(REFUSED, {"why": f"cannot write into {out} ({e.strerror or e}): nothing was written"})
        except KeyboardInterrupt as e:  # before the folder was held: only the folders Hydra made for it go
            folder.remove_empty(out, created)
            ending = _stopped(e, out, "before the job started", "nothing was written")
    _STARTED[-1] = ending
    return _end(ending, out, sweep)


def _ending(e: BaseException, cfg: DictConfig, out: Path, before: folder.Before, sweep: bool,
            finished: Ending | None) -> Ending:  # fmt: skip
    """The Ending of an exception out of the job, the folder left as it says and the line in its log."""
    try:
        ending, undone = _ended(e, cfg, out, before, sweep, finished)
    except Exception:  # the clean-up failed too (a library left half-imported by a Ctrl-C)
        folder.to_log(f"while ending the job:\n{traceback.format_exc()}")
        if stop.requested() is None and not isinstance(e, KeyboardInterrupt):
            raise
        ending, undone = _stopped(e, out, "during set-up", f"what is in {out} stays"), False
    if not undone:
        folder.to_log(ending.line)  # the folder's own record of how the job ended
    return ending


def _ended(e: BaseException, cfg: DictConfig, out: Path, before: folder.Before, sweep: bool,
           finished: Ending | None) -> tuple[Ending, bool]:  # fmt: skip
    """The outcome of an exception out of the job (``finished``: the job had written its results), the folder
    left as it says (True: as this run found it)."""
    if isinstance(e, KeyboardInterrupt) or stop.requested() is not None:  # an error a pending stop caused is it
        # (answered without torch or the results: a Ctrl-C may have cut their import short)
        where = e.where if isinstance(e, stop.Interrupted) and e.where else stop.phase()
        if finished is not None:
            return _stopped(e, out, "as the job ended", f"the job had finished: {finished.line}"), False
        if folder.checkpointed(out):
            epoch = folder.newest_epoch(out)
            what = "checkpoint written" if where == f"after epoch {epoch}" else f"the checkpoint of epoch {epoch} kept"
            resume = os.environ.get(COMMAND) or "the same command"
            return _stopped(e, out, where, f"{what} in {out}; resume: {resume}"), False
        kept = "nothing of this run was kept" + ("" if sweep else f" ({out} as it was)")
        return _stopped(e, out, where, kept), _undo(before, out, sweep)
    if isinstance(e, orphan.SweepGone):
        pid = os.environ.get(orphan.ENV, "?:?:").rsplit(":", 2)[1]
        return Ending(ORPHANED, {"pid": pid, "where": e, "folder": out}), False
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(e, ConfigError | OmegaConfBaseException):
        why = str(e) if isinstance(e, ConfigError) else cli.hydra_line(e, [])
        if os.environ.get(FULL_ERROR) and not isinstance(e, ConfigError):
            traceback.print_exc()  # omegaconf's whole text, as Hydra prints it with HYDRA_FULL_ERROR=1
        if sweep:
            folder.write_failure(out, cfg, why, "config")
        return Ending(REFUSED, {"why": why}), _undo(before, out, sweep)
    kept = folder.checkpointed(out)
    if isinstance(e, OSError):  # disk full, a read-only or immutable folder: the checkpoint already written stays
        fields = {"path": e.filename or out, "why": e.strerror or e, "errno": e.errno,
                  "kept": "the last checkpoint is kept" if kept else "no checkpoint was written yet"}  # fmt: skip
        ending = Ending(WRITE_FAILED, fields)
        folder.to_log(f"job failed: {ending.line}\n{traceback.format_exc()}")  # the traceback in train.log only
        folder.write_failure(out, cfg, ending.line.removeprefix("error: "), "exception")
        return ending, False
    if isinstance(e, MemoryError) or _torch_out_of_memory(e):
        from selpres.run.estimate import available_memory, gb

        limit, source = available_memory()
        asked = re.search(r"allocate (\d+) bytes", str(e))
        fields = {"size": f"{gb(int(asked.group(1)))} at once" if asked else type(e).__name__,
                  "available": gb(limit), "source": source,
                  "kept": "the last checkpoint is kept: run the same command again to resume" if kept else
                          "nothing of this run was kept"}  # fmt: skip
        ending = Ending(OUT_OF_MEMORY, fields)
        folder.to_log(f"job failed: {ending.line}\n{traceback.format_exc()}")
        return ending, not kept and _undo(before, out, sweep)
    if isinstance(e, Exception):  # a crash: the traceback in the job's log, the job marked failed
        folder.to_log(f"job failed:\n{traceback.format_exc()}")  # the traceback in train.log only
        folder.write_failure(out, cfg, repr(e), "exception")
        if os.environ.get(FULL_ERROR):
            traceback.print_exc()
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        error = f"{type(e).__name__}: {first}" if first else type(e).__name__
        return Ending(FAILED, {"error": error, "log": out / folder.LOG}), False
    raise e  # SystemExit and the like: not a job's outcome


def _undo(before: folder.Before, out: Path, sweep: bool) -> bool:
    """A single run's folder put back as it was found (True); a sweep's job keeps its folder (False)."""
    if not sweep:
        before.undo(out)
    return not sweep


def _stopped(e: BaseException, out: Path, where: str, kept: str) -> Ending:
    signum = e.signum if isinstance(e, stop.Interrupted) else stop.requested() or signal.SIGINT
    outcome = INTERRUPTED if signum == signal.SIGINT else TERMINATED
    return Ending(outcome, {"signal": signal.Signals(signum).name, "where": where, "kept": kept, "folder": out})


def _end(ending: Ending, out: Path, sweep: bool) -> float:
    """Say the ending (a finished job's line is logged already) and leave as its outcome says."""
    outcome, line = ending.outcome, ending.line
    if outcome.code == 0:
        return ending.value
    if sweep:  # named by its folder, among the sweep's other jobs
        line = line.removeprefix("error: ")
        line = line if str(out) in line else f"{out}: {line}"
    here = sweep and _sweeps_own_process() and outcome not in (INTERRUPTED, TERMINATED)
    if here:  # said with the others when the sweep ends (selpres.run.main), after Hydra's own words
        _UNFINISHED.append(line)
    else:  # a launcher's worker (its own console or log), or a run that ends here
        print(line, file=sys.stderr)
    if outcome is ORPHANED:  # this worker process stops (its launcher would hand it the next job)
        logging.shutdown()
        os._exit(outcome.code)
    if not sweep:
        sys.exit(outcome.code)
    if outcome in (INTERRUPTED, TERMINATED):
        if os.environ.get("SUBMITIT_EXECUTOR") == "slurm":
            # under SLURM the job's process exits with the signal's status: submitit writes no result, so the sweep
            # keeps waiting while SLURM requeues the job (preemption, `scontrol requeue`), which then resumes; a
            # result written here would count the job as done (submitit: done once a result file exists)
            sys.exit(outcome.code)
        if _sweeps_own_process():  # the basic launcher: the signal stops the sweep
            raise stop.Interrupted(stop.requested() or signal.SIGINT, "(said)")
    raise SweepJobError(line) from None


def _sweeps_own_process() -> bool:
    """Whether this process launched the sweep (its jobs run here: the basic launcher, joblib's n_jobs=1)."""
    return os.environ.get(orphan.ENV, "").split(":")[1:2] == [str(os.getpid())] and orphan.sweep_parent() is None


def stopped_outside(signum: int | None) -> tuple[str | None, int]:
    """The line and exit status of a command a signal stopped outside any job's answer to it (while Hydra composed,
    between a sweep's jobs, after the last one); no line when a job said it already."""
    signum = signum or signal.SIGINT
    name, last = signal.Signals(signum).name, _STARTED[-1] if _STARTED else None
    if last is not None and last.outcome in (INTERRUPTED, TERMINATED):
        return None, stop.STATUS[signum]
    if last is not None and last.outcome.code != 0 and len(_STARTED) == 1:  # it said how it ended, and was exiting
        return None, last.outcome.code
    for at, created in _CREATED.items():
        folder.remove_empty(at, created)
    if _sweeps_own_process():
        return f"stopped by {name}: the sweep stopped; the same command runs what is unfinished", stop.STATUS[signum]
    if not _STARTED:
        return f"stopped by {name} before the job started: nothing was written", stop.STATUS[signum]
    if last is not None and last.outcome.code == 0 and len(_STARTED) == 1:
        return f"stopped by {name} as the job ended: the job had finished: {last.line}", stop.STATUS[signum]
    return f"stopped by {name} between jobs: the same command runs what is left", stop.STATUS[signum]


def _check_name(hc, sweep: bool) -> None:
    """``name=`` names a sweep's folder; a single run's folder is named by its overrides, so ``name=`` there would be
    silently ignored: refuse it."""
    overrides = OmegaConf.to_container(hc.overrides.task) if hc is not None else []  # unresolved: seed=${x} is text
    given = [o.split("=", 1)[1] for o in overrides if o.split("=", 1)[0] == "name"]
    if given and not sweep:
        raise ConfigError(
            "name",
            given[0],
            "only with -m (a sweep's folder outputs/sweeps/<name>/); a single run's folder is named by its "
            "overrides (or hydra.run.dir=...)",
        )


def _torch_out_of_memory(e: BaseException) -> bool:
    """torch's failed allocation: a RuntimeError ("DefaultCPUAllocator: can't allocate memory"), not MemoryError."""
    return isinstance(e, RuntimeError) and ("can't allocate memory" in str(e) or "out of memory" in str(e).lower())
