"""SIGTERM and SIGUSR1: stop with a checkpoint written at once, one line and exit 143.

Under SLURM, preemption and ``scontrol requeue`` send SIGTERM and SIGKILL ``KillWait`` seconds later, and
``--signal=USR1@<s>`` sends SIGUSR1 before the time limit. Python's default ends the job at once, unsaved: the
re-run resumed from the last periodic checkpoint, and a launcher that ignored the signal (submitit) kept training
unsaved for the whole grace period. Here the handler (installed by ``python train.py`` and, for a sweep's job in a
launcher's worker process where ``train.py`` never ran, by ``run_job``: :func:`install`) only records the signal
while the training loop runs: the loop finishes the epoch under way (shuffles are per epoch, so a checkpoint
between epochs is the only exact one), writes a checkpoint and raises :class:`Terminated`, which the command line
reports in one line with status 143 (128 + 15, as a shell reports a SIGTERM); a sweep's job ends as
``selpres.run.cli`` says. Outside the loop (set-up, Hydra writing its record) the handler raises
:class:`Terminated` where the process is, and what this run created is removed, as for Ctrl-C.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

SIGNALS = (signal.SIGTERM, signal.SIGUSR1)
STATUS = 143  # the exit status of a job stopped by a signal here (128 + SIGTERM)
_state = {"signal": None, "in_loop": False}


class Terminated(BaseException):
    """A SIGTERM or SIGUSR1 stopped the job (a BaseException, as KeyboardInterrupt: no ``except Exception``
    in set-up swallows it)."""

    def __init__(self, signum: int, where: str = ""):
        self.signum, self.where = signum, where
        super().__init__(f"stopped by {signal.Signals(signum).name}" + (f" {where}" if where else ""))


def _handler(signum, frame) -> None:
    if _state["signal"] is None:
        _state["signal"] = signum
    if not _state["in_loop"]:
        raise Terminated(signum)


def install() -> None:
    """Handle SIGTERM and SIGUSR1 in this process (call from the main thread), forgetting an earlier job's signal."""
    _state["signal"] = None
    for s in SIGNALS:
        signal.signal(s, _handler)


@contextmanager
def handling():
    """SIGTERM and SIGUSR1 handled here for one job, then the handlers from before it again: a sweep's worker
    (loky, submitit) runs its launcher's code between jobs. Only the main thread may set a handler; a job in
    another thread runs without."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {s: signal.getsignal(s) for s in SIGNALS}
    install()
    try:
        yield
    finally:
        for s, handler in before.items():
            if handler is not None:  # None: set outside Python, cannot be put back
                signal.signal(s, handler)


def requested() -> int | None:
    """The signal that asked the job to stop, if one has."""
    return _state["signal"]


@contextmanager
def loop():
    """While the training loop runs, a signal is a request it acts on at the end of the epoch under way."""
    _state["in_loop"] = True
    try:
        yield
    finally:
        _state["in_loop"] = False
