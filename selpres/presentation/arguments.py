"""The library's arguments to ``SelectivePresentation``: a schedule and a priority order from plain Python values.

The CLI's checks (``selpres.presentation.schedule.build_schedule``, ``selpres.presentation.orders``) name config keys
(``schedule.sizes=… is not allowed``); a library caller named no key, so the same checks are run here and their
errors re-raised as ``TypeError`` (a value of the wrong kind) or ``ValueError`` (a value out of range) naming the
argument (``sizes=[0.05, 0.1, 1]: …``). One validator, two wordings.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence

import numpy as np
import torch

from selpres.errors import ConfigError
from selpres.presentation.orders import fixed_orders, priority_order
from selpres.presentation.proportions import NAMED, fit_schedule
from selpres.presentation.schedule import Schedule, build_schedule
from selpres.seeding import generator


def argument_error(e: ConfigError) -> ValueError:
    """A schedule check's ConfigError in the library's words: ``schedule.sizes`` -> ``sizes``, null -> None."""
    name = e.key.removeprefix("schedule.")
    allowed = e.allowed.replace("schedule.", "").replace("null", "None")
    return ValueError(f"{name}={e.value!r}: expected {allowed}")


def _number_list(name: str, value, kinds: tuple[type, ...], what: str) -> list:
    """Any sequence or 1-D array (numpy, torch) of numbers, as a list of its Python numbers."""
    if isinstance(value, (np.ndarray, torch.Tensor)):
        if value.ndim != 1:
            raise TypeError(f"{name}: expected a sequence or 1-D array of {what}, got shape {list(value.shape)}")
        value = value.tolist()  # numpy's and torch's ints and floats as Python's; bools stay bools (refused)
    elif isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise TypeError(f"{name}={value!r}: expected a sequence of {what}")
    for v in value:
        if isinstance(v, bool) or not isinstance(v, kinds):
            raise TypeError(f"{name}={list(value)!r}: expected a list of {what}; {v!r} is a {type(v).__name__}")
    return list(value)


def _whole(name: str, value, low: int) -> int:
    """An int (numpy ints too, not bools or floats) >= low."""
    if isinstance(value, bool):
        raise TypeError(f"{name}={value!r}: expected a whole number, not a bool")
    try:
        v = operator.index(value)
    except TypeError:
        raise TypeError(f"{name}={value!r}: expected a whole number") from None
    if v < low:
        raise ValueError(f"{name}={v}: expected a whole number >= {low}")
    return v


def schedule_of(n: int, sizes, epochs, budget, schedule) -> tuple[Schedule, str | None, str | None]:
    """(the Schedule on n patterns, the named schedule's order or None, what was applied or None).

    ``schedule``: a name of ``configs/schedule/`` (the paper's counts applied by their proportions when n is not
    1002, as the CLI does), or a built ``Schedule``; else ``sizes`` (ints: counts, floats: fractions of n),
    ``epochs`` (one per stage) and/or ``budget`` (presentations of a one-stage, compute-matched schedule; sizes
    default to [1.0] then). Counts given as ``sizes`` stay counts.
    """
    if schedule is not None:
        if sizes is not None or epochs is not None or budget is not None:
            raise TypeError("schedule: give either a schedule or sizes/epochs/budget, not both")
        if isinstance(schedule, Schedule):
            if schedule.n != n:
                raise ValueError(f"schedule ends at n = {schedule.n} patterns but there are {n}")
            return schedule, None, None
        if not isinstance(schedule, str):
            raise TypeError(f"schedule={schedule!r}: expected a name ({', '.join(NAMED)}) or a Schedule")
        from selpres.presentation.pruning import REGISTRY as PRUNING  # its light __init__: the policies' names

        if schedule in PRUNING.names:  # configs/schedule/ has them, but they choose each epoch's patterns by loss
            raise ValueError(
                f"schedule={schedule!r} chooses each epoch's patterns from the network's losses, which a sampler "
                f"does not see: run it with python train.py schedule={schedule}; "
                f"a sampler takes one of {', '.join(NAMED)}"
            )
        if schedule not in NAMED:
            raise ValueError(f"schedule={schedule!r}: expected one of {', '.join(NAMED)}")
        named = NAMED[schedule]
        sizes, budget, note = fit_schedule(named["sizes"], named["budget"], n)
        try:
            return build_schedule(sizes, named["epochs"], n, budget), named["order"], note
        except ConfigError as e:  # e.g. n = 20 patterns cannot hold 5 distinct stages
            raise ValueError(f"schedule={schedule!r} on n = {n} patterns: {argument_error(e)}") from None
    if budget is not None:
        budget = _whole("budget", budget, 1)
        sizes = [1.0] if sizes is None else sizes
    if sizes is None:
        raise TypeError("sizes: give the stage sizes (counts or fractions of n), or a named schedule=")
    sizes = _number_list("sizes", sizes, (int, float, np.integer, np.floating), "counts (ints) or fractions (floats)")
    sizes = [float(v) if isinstance(v, np.floating) else int(v) if isinstance(v, np.integer) else v for v in sizes]
    if epochs is not None:
        epochs = [int(e) for e in _number_list("epochs", epochs, (int, np.integer), "whole numbers of epochs")]
    if sizes and type(sizes[-1]) is int and sizes[-1] == 1 < n and any(isinstance(v, float) for v in sizes):
        raise ValueError(
            f"sizes={sizes!r}: the last stage is the count 1 (one pattern); the whole exemplar set is 1.0 or {n}"
        )
    try:
        return build_schedule(sizes, epochs, n, budget), None, None
    except ConfigError as e:
        raise argument_error(e) from None


def inputs_of(X) -> torch.Tensor:
    """The exemplar inputs as float64 [n, d] (a 1-D X is one input column)."""
    try:
        t = torch.as_tensor(np.asarray(X) if not isinstance(X, torch.Tensor) else X)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"X: expected the [n, d] inputs as a tensor or array, got {type(X).__name__}") from None
    if not (t.is_floating_point() or t.dtype in (torch.int64, torch.int32, torch.int16, torch.int8, torch.uint8)):
        raise TypeError(f"X: expected numbers, got a tensor of {t.dtype}")
    t = t.detach().to("cpu", torch.float64)
    if t.dim() == 1:
        t = t[:, None]
    if t.dim() != 2 or t.shape[0] == 0:
        raise ValueError(f"X: expected [n, d] inputs with n >= 1, got shape {list(t.shape)}")
    if not bool(torch.isfinite(t).all()):
        raise ValueError("X: the inputs hold NaN or inf; the stratified and coverage orders need finite inputs")
    return t


def order_of(order, X, n: int, seed: int, strata_bins: int) -> tuple[torch.Tensor, str]:
    """(the priority order of U's n indices, its name): the CLI's order of seed ``seed`` (replica 0 of a job with
    that seed), or the caller's own permutation."""
    if isinstance(order, str):
        if order not in fixed_orders():  # the stage-wise orders choose A_k in the CLI's loop, with the network
            raise ValueError(
                f"order={order!r}: expected one of {', '.join(fixed_orders())}, or a permutation of range(n); the "
                "other orders choose with the network, in the CLI's loop (python train.py with that order)"
            )
        if order != "random" and X is None:
            raise TypeError(f"order={order!r} needs the inputs X (it groups or spreads patterns by them)")
        data = X if X is not None else torch.empty(n, 0)
        return priority_order(data, order, generator(seed, "subset"), strata_bins), order
    try:
        perm = torch.as_tensor(np.asarray(order) if not isinstance(order, torch.Tensor) else order)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"order: expected a name ({', '.join(fixed_orders())}) or a permutation of range(n)") from None
    if perm.dtype.is_floating_point or perm.dtype == torch.bool or perm.dim() != 1:
        raise TypeError(f"order: expected a 1-D integer permutation of range(n), got {perm.dtype} {list(perm.shape)}")
    perm = perm.to(torch.int64)
    if not _is_permutation(perm.numpy(), n):
        raise ValueError(f"order: expected a permutation of range({n}) (each index once), got {perm.numel()} indices")
    return perm, "given"


def _is_permutation(a: np.ndarray, n: int) -> bool:
    """Each of 0..n-1 exactly once (in numpy: a job checks R = 1000 orders, ~10 us each)."""
    if a.size != n or a.min() < 0 or a.max() >= n:
        return False
    seen = np.zeros(n, dtype=bool)
    seen[a] = True
    return bool(seen.all())


def size_of(X, n, order) -> int:
    """n = |U| from whichever of X, n and a given order is there (they must agree)."""
    found = {}
    if X is not None:
        found["X"] = X.shape[0]
    if n is not None:
        found["n"] = _whole("n", n, 1)
    if not isinstance(order, (str, type(None))):
        found["order"] = len(order)
    if not found:
        raise TypeError("X: give the inputs X (or n= with order='random', or order= a permutation)")
    if len(set(found.values())) > 1:
        raise ValueError(f"X, n and order disagree on the number of patterns: {found}")
    return next(iter(found.values()))


def replicas_of(num_replicas, rank) -> tuple[int | None, int | None]:
    """Checked ``num_replicas``/``rank`` (None: from torch.distributed when the sampler is used)."""
    w = None if num_replicas is None else _whole("num_replicas", num_replicas, 1)
    r = None if rank is None else _whole("rank", rank, 0)
    if w is not None and r is not None and r >= w:
        raise ValueError(f"rank={r}: expected 0 <= rank < num_replicas = {w}")
    return w, r
