"""Presentation order: nested subsets, per-epoch permutations, determinism, stratified coverage."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from torch.utils.data import DataLoader, TensorDataset

from selpres.errors import ConfigError
from selpres.presentation import sampler as S
from selpres.presentation.orders import priority_order
from selpres.presentation.sampler import SelectivePresentationSampler, epoch_orders
from selpres.presentation.schedule import Schedule, Stage, build_schedule
from selpres.seeding import derive_seed, generator

from conftest import requires_native

PAPER_SIZES, PAPER_EPOCHS = [50, 100, 400, 800, 1002], [30] * 5
KINDS = ("stratified", "random", "coverage")


def _order(X, kind, seed=0, bins=2):
    return priority_order(X, kind, generator(seed, "subset"), bins)


def _sampler(X, kind="stratified", sizes=PAPER_SIZES, epochs=(2, 2, 2, 2, 2), seed=0, budget=None, bins=2):
    sch = build_schedule(list(sizes), None if budget else list(epochs), X.shape[0], budget)
    return SelectivePresentationSampler(_order(X, kind, seed, bins), sch, seed)


def _strata_independent(X: np.ndarray, bins: int) -> np.ndarray:
    """Own binning (not selpres.presentation.sampler.strata): ``bins`` equal-width bins per column over X's range."""
    lo, hi = X.min(0), X.max(0)
    cells = np.zeros(X.shape, dtype=np.int64)
    for j in range(X.shape[1]):
        if hi[j] > lo[j]:
            cells[:, j] = np.minimum(np.floor((X[:, j] - lo[j]) / (hi[j] - lo[j]) * bins), bins - 1)
    _, sid = np.unique(cells, axis=0, return_inverse=True)
    return sid.ravel()


def _worst_prefix_deviation(order: np.ndarray, sid: np.ndarray) -> float:
    """max over prefix sizes m = 1..n and strata s of |count_s(first m) − m·|s|/n|."""
    n, S = len(order), sid.max() + 1
    onehot = np.zeros((n, S))
    onehot[np.arange(n), sid[order]] = 1
    counts = onehot.cumsum(0)
    m = np.arange(1, n + 1)[:, None]
    return float(np.abs(counts - m * np.bincount(sid, minlength=S)[None, :] / n).max())


@pytest.fixture(scope="module")
def X(exemplar):
    return exemplar.X


# ------------------------------------------------------------------------------------ priority order


@pytest.mark.parametrize("kind", KINDS)
def test_order_is_a_permutation_and_subsets_nest(X, kind):
    n = X.shape[0]
    assert n == 1002
    s = _sampler(X, kind)
    assert sorted(s.order.tolist()) == list(range(n))
    subsets = [set(s.subset(k).tolist()) for k in range(5)]
    assert [len(a) for a in subsets] == PAPER_SIZES
    for small, big in zip(subsets, subsets[1:]):
        assert small < big  # A_i ⊂ A_{i+1}, strictly
    assert subsets[-1] == set(range(n))  # A_{p+1} = U
    # the current stage follows set_epoch
    for p in s.schedule.plan():
        s.set_epoch(p.index)
        assert s.stage == p.stage and set(s.subset().tolist()) == subsets[p.stage]


def test_unknown_order_and_bins_raise(X):
    with pytest.raises(ConfigError, match="schedule.order"):
        priority_order(X, "zigzag", generator(0))
    with pytest.raises(ConfigError, match="schedule.strata_bins"):
        priority_order(X, "stratified", generator(0), bins=0)


@pytest.mark.parametrize("kind", KINDS)
def test_order_determinism(X, kind):
    a, b, c = _order(X, kind, 7), _order(X, kind, 7), _order(X, kind, 8)
    assert torch.equal(a, b)
    assert not torch.equal(a, c)
    assert not torch.equal(a[:50].sort().values, c[:50].sort().values)  # different A1, not just reordered


def test_stratified_and_random_orders_differ(X):
    assert not torch.equal(_order(X, "stratified", 3), _order(X, "random", 3))


# ----------------------------------------------------------------------------------------- epochs


@pytest.mark.parametrize("kind", KINDS)
def test_every_epoch_is_a_permutation_of_the_current_subset(X, kind):
    s = _sampler(X, kind)
    total = 0
    for p in s.schedule.plan():
        s.set_epoch(p.index)
        idx = s.epoch_indices()
        assert idx.dtype == torch.int64 and idx.dim() == 1
        assert len(s) == p.presentations == p.size == idx.numel()
        assert sorted(idx.tolist()) == sorted(s.order[: p.size].tolist())  # no repeats, no drops
        assert list(iter(s)) == idx.tolist()
        total += idx.numel()
    assert total == s.schedule.presentations == 2 * sum(PAPER_SIZES)


def test_partial_epoch_is_a_prefix_of_that_epochs_permutation(X):
    n, budget = X.shape[0], 3 * X.shape[0] + 420
    s = _sampler(X, budget=budget, sizes=[1.0])
    plan = s.schedule.plan()
    assert [p.presentations for p in plan] == [n, n, n, 420]
    s.set_epoch(3)
    part = s.epoch_indices()
    assert len(s) == 420 == part.numel() == len(set(part.tolist()))
    # the same epoch, had it been a full one: the partial epoch presents its first 420 patterns
    full = SelectivePresentationSampler(s.order, Schedule((Stage(n, 4),)), s.seed)
    full.set_epoch(3)
    whole = full.epoch_indices()
    assert sorted(whole.tolist()) == list(range(n))
    assert torch.equal(part, whole[:420])
    got = 0
    for p in plan:
        s.set_epoch(p.index)
        got += len(s)
    assert got == budget


def test_epochs_reshuffle(X):
    s = _sampler(X, epochs=(3, 3, 3, 3, 3))
    for stage in range(5):
        orders = []
        for p in s.schedule.plan():
            if p.stage == stage:
                s.set_epoch(p.index)
                orders.append(s.epoch_indices().tolist())
        assert len(orders) == 3
        assert orders[0] != orders[1] and orders[1] != orders[2] and orders[0] != orders[2]
        assert sorted(orders[0]) == sorted(orders[1])


def test_epoch_order_is_a_function_of_seed_and_epoch(X):
    """Same seed ⇒ identical epochs (also out of order, as after a resume); different seed ⇒ different."""
    a, b, c = _sampler(X, seed=1), _sampler(X, seed=1), _sampler(X, seed=2)
    plan = a.schedule.plan()
    seen_a = {}
    for p in plan:
        a.set_epoch(p.index)
        seen_a[p.index] = a.epoch_indices()
    for p in reversed(plan):
        b.set_epoch(p.index)
        c.set_epoch(p.index)
        assert torch.equal(b.epoch_indices(), seen_a[p.index])
        assert not torch.equal(c.epoch_indices(), seen_a[p.index])
    a.set_epoch(0)
    assert torch.equal(a.epoch_indices(), a.epoch_indices())  # asking twice does not advance anything


def test_set_epoch_out_of_range_raises(X):
    s = _sampler(X)
    E = len(s.schedule.plan())
    assert E == 10
    s.set_epoch(E - 1)
    for bad in (E, E + 5, -1):
        with pytest.raises(IndexError):
            s.set_epoch(bad)
    assert s.epoch == E - 1  # unchanged by the failed calls


def test_order_length_must_match_schedule(X):
    sch = build_schedule([10, 20], [1, 1], 20)
    with pytest.raises(ValueError):
        SelectivePresentationSampler(torch.arange(19), sch, 0)


def test_works_as_a_dataloader_sampler(X):
    s = _sampler(X, sizes=[50, 1002], epochs=(1, 1))
    dl = DataLoader(TensorDataset(torch.arange(X.shape[0])), sampler=s, batch_size=16)
    s.set_epoch(0)
    got = torch.cat([b[0] for b in dl])
    assert torch.equal(got, s.epoch_indices())


# ---------------------------------------------------------------------------------------- coverage


@pytest.mark.parametrize("bins", [2, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stratified_prefixes_cover_every_stratum_proportionally(X, bins, seed):
    """Every prefix of the stratified order (so every A_i, whatever n_i) is a proportional stratified
    sample: each stratum's count within 2 of m·|s|/n, for every m = 1..n."""
    sid = _strata_independent(X.numpy(), bins)
    assert sid.max() + 1 > 10  # the real data spreads over many strata
    order = _order(X, "stratified", seed, bins).numpy()
    assert _worst_prefix_deviation(order, sid) <= 2.0


def test_random_order_is_not_stratified(X):
    """The same check tells random growth apart: on the real data it is off by far more than 2."""
    sid = _strata_independent(X.numpy(), 2)
    worst = [_worst_prefix_deviation(_order(X, "random", seed).numpy(), sid) for seed in range(3)]
    assert min(worst) > 4.0


def test_stratified_on_skewed_synthetic_data():
    """One stratum holding most of the data, a few tiny ones: still proportional in every prefix."""
    g = torch.Generator().manual_seed(5)
    big = torch.rand(900, 6, generator=g, dtype=torch.float64) * 0.4  # all in the low cell of every column
    small = 0.6 + torch.rand(100, 6, generator=g, dtype=torch.float64) * 0.4
    small[:50, 0] -= 0.6  # some mixed cells
    X = torch.cat([big, small])
    sid = _strata_independent(X.numpy(), 2)
    assert _worst_prefix_deviation(priority_order(X, "stratified", generator(1), 2).numpy(), sid) <= 2.0
    assert _worst_prefix_deviation(priority_order(X, "random", generator(1), 2).numpy(), sid) > 2.0


# ------------------------------------------------------------- property: schedules from any config


@st.composite
def schedule_inputs(draw):
    """Half well-formed schedules (counts or fractions, sometimes a budget), half anything at all."""
    n = draw(st.integers(1, 40))
    kind = draw(st.sampled_from(KINDS))
    bins = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**31))
    if draw(st.booleans()):
        k = draw(st.integers(1, min(5, n)))
        sizes = [n]
        if n > 1:
            inner = st.lists(st.integers(1, n - 1), min_size=k - 1, max_size=k - 1, unique=True)
            sizes = sorted(draw(inner)) + sizes
        as_fraction = draw(st.lists(st.booleans(), min_size=len(sizes), max_size=len(sizes)))
        sizes = [s / n if f else s for s, f in zip(sizes, as_fraction)]
        epochs, budget = draw(st.lists(st.integers(1, 3), min_size=len(sizes), max_size=len(sizes))), None
        if len(sizes) == 1 and draw(st.booleans()):
            epochs, budget = None, draw(st.integers(1, 4 * n))
        return n, sizes, epochs, budget, kind, bins, seed
    k = draw(st.integers(1, 5))
    elem = st.one_of(
        st.integers(-2, n + 2),
        st.floats(-0.2, 1.2, allow_nan=False),
        st.sampled_from([1.0, float("nan"), float("inf"), True]),
    )
    sizes = draw(st.lists(elem, min_size=k, max_size=k))
    if draw(st.booleans()):
        sizes = sizes[:-1] + [n]
    epochs = draw(st.one_of(st.none(), st.lists(st.integers(-1, 4), min_size=max(0, k - 1), max_size=k + 1)))
    budget = draw(st.one_of(st.none(), st.none(), st.integers(-2, 4 * n)))
    return n, sizes, epochs, budget, kind, bins, seed


def _valid_int_schedule(n, sizes, epochs, budget):
    """Independent validity rule for all-integer sizes (no fractions to round)."""
    ok_sizes = (
        len(sizes) > 0 and all(s > 0 for s in sizes) and all(b > a for a, b in zip(sizes, sizes[1:])) and sizes[-1] == n
    )
    if budget is not None:
        return ok_sizes and len(sizes) == 1 and budget > 0 and epochs is None
    return ok_sizes and epochs is not None and len(epochs) == len(sizes) and all(e > 0 for e in epochs)


@settings(max_examples=150, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(schedule_inputs())
def test_any_schedule_builds_or_raises_config_error_and_presents_exactly_its_plan(args):
    n, sizes, epochs, budget, kind, bins, seed = args
    try:
        sch = build_schedule(sizes, epochs, n, budget)
        event("built")
    except ConfigError as e:
        assert e.key in ("schedule.sizes", "schedule.epochs", "schedule.budget")
        if all(type(s) is int for s in sizes):
            assert not _valid_int_schedule(n, sizes, epochs, budget), f"valid schedule rejected: {e}"
        return
    if all(type(s) is int for s in sizes):
        assert _valid_int_schedule(n, sizes, epochs, budget)
        assert sch.sizes == sizes
    assert sch.n == n and all(b > a for a, b in zip(sch.sizes, sch.sizes[1:]))
    expected_total = budget if budget is not None else sum(s * e for s, e in zip(sch.sizes, epochs))

    g = torch.Generator().manual_seed(seed)
    X = torch.randint(0, 3, (n, 6), generator=g).double()  # ties and constant columns on purpose
    order = priority_order(X, kind, generator(seed, "subset"), bins)
    assert sorted(order.tolist()) == list(range(n))
    sampler = SelectivePresentationSampler(order, sch, seed)
    plan = sch.plan()
    assert len(plan) == sch.total_epochs > 0
    total = 0
    for p in plan:
        sampler.set_epoch(p.index)
        idx = sampler.epoch_indices().tolist()
        subset = set(order[: sch.stages[p.stage].size].tolist())
        assert len(idx) == len(sampler) == p.presentations
        assert len(set(idx)) == len(idx) and set(idx) <= subset
        if p.presentations == p.size:
            assert set(idx) == subset
        total += len(idx)
    assert total == sum(p.presentations for p in plan) == sch.presentations == expected_total
    with pytest.raises(IndexError):
        sampler.set_epoch(len(plan))


# -------------------------------------------------------------- shuffles: the definition, written plainly

_MASK64 = 2**64 - 1
_GOLDEN = 0x9E3779B97F4A7C15


def _mix_int(z: int) -> int:
    """splitmix64's finaliser on a Python int (arbitrary precision, reduced mod 2**64 by hand)."""
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


def _plain_hashes(seed: int, epoch: int, size: int) -> list[int]:
    key = derive_seed(seed, "shuffle")
    base = _mix_int(key ^ _mix_int((epoch + _GOLDEN) & _MASK64))
    return [_mix_int((base + i * _GOLDEN) & _MASK64) for i in range(size)]


def _plain_epoch_order(order: list[int], seed: int, epoch: int, size: int, count: int) -> list[int]:
    """The shuffle's definition: positions of the current set sorted by hash(key, epoch, position)."""
    h = _plain_hashes(seed, epoch, size)
    return [order[i] for i in sorted(range(size), key=h.__getitem__)[:count]]


@pytest.fixture(params=["native", "numpy"])
def shuffles(request, monkeypatch):
    """Each test runs with the native shuffles (kernels/shuffle.c) and with the numpy ones."""
    if request.param == "native":
        if S.native_shuffles()[0] is None:
            pytest.skip(f"native shuffles unavailable: {S.native_shuffles()[1]}")
    else:
        monkeypatch.setattr(S, "native_shuffles", lambda: (None, "forced by the test"))
    return request.param


@pytest.mark.parametrize(
    "n, sizes, epochs, budget, R",
    [
        (1002, [50, 100, 400, 800, 1002], [1, 2, 1, 1, 2], None, 40),  # paper sets, > 1 block of replicas
        (1, [1], [3], None, 2),
        (2, [1, 2], [2, 2], None, 3),
        (2048, [1, 2047, 2048], [1, 1, 1], None, 3),  # the largest sets sorted on 32-bit keys ...
        (5000, [2049, 5000], [1, 1], None, 2),  # ... and the smallest on 64-bit keys
        (1002, [1.0], None, 3 * 1002 + 420, 5),  # a partial last epoch
        (300, [1.0], None, 299, 4),  # a single, partial epoch
        (70_000, [1.0], [1], None, 2),  # a large set: 2^17 buckets in the native bucket sort
    ],
)
def test_epoch_orders_equal_the_plain_definition(n, sizes, epochs, budget, R, shuffles):
    """Bit-identical to the definition for every replica, epoch, set size and partial count; each replica's
    row equals its solo run (the sampler of seed s + r alone): resume and 'replica r = seed s + r' rely on
    both."""
    sch = build_schedule(sizes, epochs, n, budget)
    g = torch.Generator().manual_seed(n + R)
    seeds = [1000 * n + 17 * r for r in range(R)]
    samplers = [SelectivePresentationSampler(torch.randperm(n, generator=g), sch, s) for s in seeds]
    for p in sch.plan():
        for s in samplers:
            s.set_epoch(p.index)
        got = epoch_orders(samplers)
        assert got.dtype == torch.int64 and got.shape == (R, p.presentations) and got.is_contiguous()
        for r, s in enumerate(samplers):
            want = _plain_epoch_order(s.order.tolist(), seeds[r], p.index, p.size, p.presentations)
            assert got[r].tolist() == want, (p, r)
        assert torch.equal(epoch_orders(samplers[1:2])[0], got[1])


@requires_native
def test_the_job_records_which_shuffles_ran(monkeypatch):
    assert S.shuffle_implementation() == "native"
    monkeypatch.setattr(S, "native_shuffles", lambda: (None, "no compiler"))
    assert S.shuffle_implementation() == "numpy (no compiler)"


def test_orders_written_into_a_reused_buffer_equal_fresh_ones(X, shuffles):
    """A job reuses one buffer every epoch: each epoch's orders are still exactly that epoch's, in the
    buffer's memory (a smaller current set uses its front)."""
    sch = build_schedule([100, 1002], [2, 2], 1002)
    samplers = [
        SelectivePresentationSampler(priority_order(X, "stratified", generator(s, "subset")), sch, s) for s in range(5)
    ]
    buffer = torch.full((5 * 1002,), -1, dtype=torch.int64)
    for p in sch.plan():
        for s in samplers:
            s.set_epoch(p.index)
        got = epoch_orders(samplers, buffer)
        assert got.data_ptr() == buffer.data_ptr() and got.shape == (5, p.presentations)
        assert torch.equal(got, epoch_orders(samplers))
