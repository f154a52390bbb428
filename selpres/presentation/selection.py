"""The network's scores a selector may ask for, and what choosing costs.

One forward pass of all replicas over U (``errors_of``: every replica's per-pattern squared error), run on one thread
(``one_thread``). A selector that scores candidates this way is charged ``schedule.selection_cost`` of a training
presentation per candidate (a stage-wise order per enlargement, rounded up to whole presentations:
``orders.selection_charge``; Selective Backprop per candidate it scores), into the job's ledger
(``selpres.presentation.selector.Ledger``). Why the default is 1/3, and what was measured:
``docs/studies/selection.md`` ("What choosing costs"). Stratified draws (A_1, ``reselect``) need no network and are
charged nothing.
"""

from __future__ import annotations

from contextlib import contextmanager

import torch


@contextmanager
def one_thread():
    """Choosing runs on one torch thread: its blocks are too small to share (with two threads on a busy
    machine, R = 1000, one enlargement took 0.8 s instead of 0.07 s: OpenMP waits at every small op), and
    ``threads`` is not part of a job's identity, so the choice must not depend on it (BLAS may round
    differently with another thread count)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def pattern_errors(outputs: torch.Tensor, Y: torch.Tensor) -> torch.Tensor:
    """Squared error of every replica on every pattern, summed over outputs: [R, n, out], [n, out] -> [R, n].
    A diverged replica's NaN counts as +inf, so its choice stays deterministic."""
    d = outputs - Y
    return torch.nan_to_num_(d.square_().sum(-1), nan=float("inf"))  # in place: [R, n, out] is 115 MB on the PUMA


def errors_of(engine, X: torch.Tensor, Y: torch.Tensor) -> torch.Tensor:
    """Every replica's per-pattern squared error on (X, Y) [n, in], [n, out] -> [R, n], from one
    ``engine.predict`` call."""
    with torch.no_grad():
        return pattern_errors(engine.predict(X), Y)
