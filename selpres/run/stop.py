"""Ctrl-C, SIGTERM and SIGUSR1: one request to stop, kept until the job has answered it.

A signal is first of all *recorded* (:func:`requested`), and only then raised where the process is
(:class:`Interrupted`, a ``KeyboardInterrupt``), so that a set-up that takes seconds stops at once. The record is
what makes the stop certain: an exception raised at an arbitrary point can be lost (a C extension's start-up that
clears it, a library's clean-up that replaces it by an error of its own half-built state, a finalizer that
swallows it), while the record stays, and the job asks for it where it can answer it: when its task function
starts, at the end of every epoch, and once more before the command exits (:func:`check`); a raise that Python
itself cannot pass on (in a finalizer) is dropped without its "Exception ignored" traceback. A process that
received one of these signals therefore never ends as if it had not (exit 0), nor as a broken config (exit 1).

While a stretch that must not be cut runs (an epoch with its checkpoint, the job's own clean-up:
:func:`deferred`) a signal is recorded and not raised; the training loop answers it at the end of the epoch
under way by writing a checkpoint there (shuffles are per epoch: a checkpoint between epochs is the only exact
one) and raising :class:`Interrupted`, so a second Ctrl-C during that checkpoint's write cannot cut it.
Under SLURM, preemption and ``scontrol requeue`` send SIGTERM (SIGKILL ``KillWait`` seconds later), and
``--signal=USR1@<s>`` SIGUSR1 before the time limit: the same stop. What the command prints and its exit status
are :mod:`selpres.run.job`'s (its table of outcomes).
"""

from __future__ import annotations

import signal
import sys
import threading
from contextlib import contextmanager

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1)
STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGUSR1: 143}  # 128 + signal, as a shell reports it
_state = {"signal": None, "deferred": 0, "phase": "during set-up"}


class Interrupted(KeyboardInterrupt):
    """A signal of :data:`SIGNALS` stopped the job; ``where`` says where (``after epoch 12 (checkpoint written)``).
    A ``KeyboardInterrupt``: no ``except Exception`` swallows it, and libraries that clean up after a Ctrl-C
    (subprocess, joblib) do so for all three signals."""

    def __init__(self, signum: int, where: str = ""):
        self.signum, self.where = signum, where
        super().__init__(f"stopped by {signal.Signals(signum).name}" + (f" {where}" if where else ""))

    @property
    def status(self) -> int:
        return STATUS[self.signum]

    def __reduce__(self):
        return type(self), (self.signum, self.where)


def _handler(signum, frame) -> None:
    if _state["signal"] is None:  # the first signal is the request; a second one only repeats it
        _state["signal"] = signum
    if not _state["deferred"]:
        raise Interrupted(signum)


def _unraisable(info) -> None:
    """An :class:`Interrupted` raised where Python cannot pass it on (a finalizer, a weakref callback such as
    importlib's module-lock clean-up) is dropped quietly: the record answers it. Anything else goes to the hook
    that was there."""
    if not isinstance(info.exc_value, Interrupted):
        _state["unraisable"](info)


def installed() -> bool:
    return signal.getsignal(signal.SIGINT) is _handler


def install() -> None:
    """Handle the signals here (the main thread), with no request pending: a process's first call, before it
    imports anything that takes time."""
    _state["signal"], _state["deferred"] = None, 0
    if sys.unraisablehook is not _unraisable:
        _state["unraisable"], sys.unraisablehook = sys.unraisablehook, _unraisable
    for s in SIGNALS:
        signal.signal(s, _handler)


@contextmanager
def handling():
    """The signals handled for one job, then the handlers from before it again: a sweep's job may run in a
    launcher's worker (loky, submitit) where the command's :func:`install` never ran, and the worker runs its
    launcher's code between jobs. Where they are handled already (the command's process) nothing changes and a
    pending request stays pending. Only the main thread may set handlers; a job in another thread runs without."""
    if installed() or threading.current_thread() is not threading.main_thread():
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


def check(where: str = "") -> None:
    """Raise :class:`Interrupted` if a signal asked to stop (its raise may have been lost on the way)."""
    if _state["signal"] is not None:
        raise Interrupted(_state["signal"], where)


def phase(now: str | None = None) -> str:
    """Where the job is, for a stop that does not say (``during set-up``, ``as it finished``); ``now`` sets it."""
    if now is not None:
        _state["phase"] = now
    return _state["phase"]


@contextmanager
def loop():
    """The training loop: a signal is answered at the end of the epoch under way (the loop raises
    :class:`Interrupted` there, saying after which epoch), and what follows the loop is the job's finish."""
    with deferred():
        yield
    phase("as it finished")


@contextmanager
def deferred():
    """Inside, a signal is recorded and not raised: the code inside answers it where it can (the loop, at the end
    of the epoch under way) or the caller does after it (:func:`check`)."""
    _state["deferred"] += 1
    try:
        yield
    finally:
        _state["deferred"] -= 1
