"""How a job ends: the one table of outcomes that :mod:`selpres.run.job` ends every job with.

Each row is what the command does for that outcome: its exit status, its one last line (a template the job fills
in), what ``results.json`` says afterwards and what a sweep does with the job. ``docs/usage.md`` prints the same
table, and the tests provoke every row for real (``tests/test_outcomes.py`` walks it).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Outcome:
    """One way a job ends (a row of :data:`OUTCOMES`)."""

    name: str
    code: int  # the exit status of `python train.py` (a single run)
    line: str  # its last line, filled in by the job (str.format)
    results: str  # what results.json says afterwards
    sweep: str  # what a sweep does with the job


DONE = Outcome("done", 0, "results: {results}", "complete (diverged when every replica diverged)", "counted")
RESUMED = Outcome(
    "resumed", 0, "results: {results} (resumed from epoch {epoch})", "complete, resumed_from_epoch set", "counted"
)
SKIPPED = Outcome(
    "skipped", 0, "already done: {results} (overwrite=true to run it again)", "as it was", "counted, not run again"
)
REFUSED = Outcome(
    "refused",
    2,
    "error: {why}",  # the key, the value and what is allowed (a config, Hydra's own refusal, a folder it cannot use)
    "not written: the folder as it was (a sweep's job: failed)",
    "fails alone, named; the others run",
)
PROTECTED = Outcome(
    "protected",
    2,
    "error: {folder} holds a finished job of another config ({differences}): overwrite=true replaces it, or give "
    "this one another folder (hydra.run.dir=...)",
    "the finished job's, untouched",
    "fails alone, named; the others run",
)
BUSY = Outcome(
    "busy",
    2,
    "error: {folder} is in use by {holder} (one writer per job folder); nothing was touched",
    "the holder's, untouched",
    "skipped, named; the others run",
)
INTERRUPTED = Outcome(
    "interrupted",
    130,
    "stopped by {signal} {where}: {kept}",  # kept: the checkpoint at the stop, where it is and the command to resume
    "not written: the checkpoint at the stop is kept (else the folder as it was)",
    "the sweep stops (a launcher worker's job fails alone)",
)
TERMINATED = Outcome(
    "terminated",
    143,
    INTERRUPTED.line,  # SIGTERM or SIGUSR1: the same stop as a Ctrl-C
    INTERRUPTED.results,
    "fails alone (under SLURM its process exits 143: SLURM requeues the job, which resumes)",
)
ORPHANED = Outcome(
    "orphaned",
    3,
    "the sweep that launched this job is gone (PID {pid}): stopped {where}; run the sweep again to resume {folder}",
    "not written: the checkpoint is kept",
    "the worker process stops",
)
OUT_OF_MEMORY = Outcome(
    "out of memory",
    2,
    "error: out of memory: an allocation of {size} failed with {available} available ({source}); lower replicas or "
    "free memory; {kept}",
    "not written (a single run with no checkpoint: the folder as it was)",
    "fails alone, named",
)
WRITE_FAILED = Outcome(
    "write failure",
    2,
    "error: cannot write {path}: {why} (errno {errno}); {kept}: run the same command again once it can be written",
    "failed (where it can still be written); the last checkpoint is kept",
    "fails alone, named",
)
FAILED = Outcome(
    "failed", 1, "error: the job failed ({error}); the traceback is in {log}", "failed", "fails alone, named"
)
OUTCOMES = (
    DONE, RESUMED, SKIPPED, REFUSED, PROTECTED, BUSY, INTERRUPTED, TERMINATED, ORPHANED, OUT_OF_MEMORY, WRITE_FAILED,
    FAILED,
)  # fmt: skip


@dataclass
class Ending:
    """How one job ended: its outcome, the values its line is filled in with, and (done) the sweepers' objective."""

    outcome: Outcome
    fields: dict = field(default_factory=dict)
    value: float | None = None

    @property
    def line(self) -> str:
        return self.outcome.line.format(**self.fields)
