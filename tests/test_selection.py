"""Stage-wise orders (selpres.presentation.selection): each order's defining property against an independent
computation, and the cost of choosing, written out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from selpres.data.task import load_task
from selpres.engines.model import BPN, load_into
from selpres.errors import ConfigError
from selpres.presentation.orders import priority_order, selection_charge
from selpres.presentation.orders._loss import enlarge_by_loss
from selpres.presentation.orders.reselect import reselected_orders
from selpres.presentation.partition import strata
from selpres.presentation.selection import pattern_errors
from selpres.run.resolve import resolve
from selpres.run.specs import task_specs
from selpres.run.train import Clock, run_epoch, start, train
from selpres.seeding import generator

from conftest import cfg_of, numbers

SIZES = [50, 100, 400, 800, 1002]
N = 1002


def _raw_X(cfg) -> torch.Tensor:
    return load_task(*task_specs(cfg)).exemplar.X


# ------------------------------------------------------------------------------------ the pure step


def _enlarged_by_definition(order: list[int], err: dict, kept: int, added: int, hard: bool) -> list[int]:
    """The definition, by a plain stable sort: the first ``added`` candidates by error (ties: the earlier
    candidate), then joined to A_{k-1} in the candidates' own order, the others after them."""
    tail = order[kept:]
    best = sorted(range(len(tail)), key=lambda j: (-err[tail[j]] if hard else err[tail[j]], j))[:added]
    return order[:kept] + [tail[j] for j in sorted(best)] + [t for j, t in enumerate(tail) if j not in best]


def test_enlarge_by_loss_on_a_hand_worked_example():
    """Row 0: A_{k-1} = {4, 2}; candidates, in stratified order, 3, 1, 0 with errors 0.5, 0.2, 0.5: the tie
    between 3 and 0 goes to 3 (the earlier candidate), though 0 has the lower index. Row 1: errors rising
    with the index, no ties."""
    orders = torch.tensor([[4, 2, 3, 1, 0], [0, 1, 2, 3, 4]])
    errors = torch.tensor([[0.5, 0.2, 9.0, 0.5, 1.0], [1.0, 2.0, 3.0, 4.0, 5.0]], dtype=torch.float64)
    expected = {  # (added, hard) -> rows, worked out by hand
        (1, True): [[4, 2, 3, 1, 0], [0, 1, 4, 2, 3]],
        (2, True): [[4, 2, 3, 0, 1], [0, 1, 3, 4, 2]],
        (1, False): [[4, 2, 1, 3, 0], [0, 1, 2, 3, 4]],
        (2, False): [[4, 2, 3, 1, 0], [0, 1, 2, 3, 4]],
        (3, True): [[4, 2, 3, 1, 0], [0, 1, 2, 3, 4]],
    }
    for (added, hard), rows in expected.items():
        assert enlarge_by_loss(orders, errors, 2, added, hard).tolist() == rows, (added, hard)


@pytest.mark.parametrize("hard", [True, False])
def test_enlarge_by_loss_equals_the_stable_sort_definition_with_many_ties(hard):
    """Random orders and errors from only five values (ties everywhere, and inf): the partition equals the
    plain stable-sort definition on every row."""
    g = torch.Generator().manual_seed(3)
    R, n = 40, 60
    orders = torch.stack([torch.randperm(n, generator=g) for _ in range(R)])
    values = torch.tensor([0.0, 0.25, 0.5, 1.0, math.inf], dtype=torch.float64)
    errors = values[torch.randint(5, (R, n), generator=g)]
    for kept, added in [(0, 1), (5, 10), (20, 17), (30, 30), (59, 1)]:
        got = enlarge_by_loss(orders, errors, kept, added, hard)
        for r in range(R):
            err = dict(enumerate(errors[r].tolist()))
            assert got[r].tolist() == _enlarged_by_definition(orders[r].tolist(), err, kept, added, hard)


def test_a_diverged_replicas_nan_errors_count_as_largest():
    out = torch.tensor([[[0.5], [float("nan")], [0.1]]], dtype=torch.float64)
    e = pattern_errors(out, torch.tensor([[0.4], [0.4], [0.4]], dtype=torch.float64))
    assert e[0, 1] == math.inf
    assert e[0, 0].item() == pytest.approx(0.01) and e[0, 2].item() == pytest.approx(0.09)
    assert enlarge_by_loss(torch.tensor([[0, 1, 2]]), e, 0, 1, True).tolist() == [[1, 0, 2]]


# ------------------------------------------------------------------------- loss orders in the real loop


@pytest.mark.parametrize("kind", ["loss_high", "loss_low"])
def test_each_enlargement_adds_the_candidates_the_current_network_errs_most_or_least_on(kind):
    """In the training loop: A_1 is the seed's stratified A_1; at each stage start, A_{k-1} stays the prefix
    (nesting) and the n_k - n_{k-1} added patterns are the top ones of U \\ A_{k-1} by the squared error
    of that replica's network at that moment, computed here by a plain loop over BPN forward passes, ties
    by the stratified order; the chosen join A_k, and the other candidates stay, in the stratified order."""
    hard = kind == "loss_high"
    cfg = cfg_of(f"schedule.order={kind}", "replicas=3", "schedule.epochs=[2,1,1,1,1]", "engine=torch", "seed=7")
    clock = Clock()
    job = start(resolve(cfg), None, clock)
    prob = job.prob
    strat = [priority_order(_raw_X(cfg), "stratified", generator(s, "subset"), 2) for s in prob.seeds]
    rank = [{int(i): j for j, i in enumerate(o)} for o in strat]
    for r, s in enumerate(prob.samplers):
        assert torch.equal(s.order[:50], strat[r][:50])
    starts = 0
    for ep in prob.plan:
        k = ep.stage
        if k == 0 or prob.plan[ep.index - 1].stage == k:
            run_epoch(job, ep, clock)
            continue
        starts += 1
        params = job.engine.params()
        prev = [s.order[: SIZES[k - 1]].tolist() for s in prob.samplers]
        run_epoch(job, ep, clock)
        for r, s in enumerate(prob.samplers):
            assert s.order[: SIZES[k - 1]].tolist() == prev[r]  # A_{k-1} ⊂ A_k, as the prefix
            with torch.no_grad():
                net = load_into(BPN((6, 13, 2)), params, r)
                err = [float(((net(prob.X[i : i + 1]) - prob.Y[i : i + 1]) ** 2).sum()) for i in range(N)]
            kept = set(prev[r])
            cands = [i for i in range(N) if i not in kept]
            expected = sorted(cands, key=lambda i: (-err[i] if hard else err[i], rank[r][i]))
            added, rest = s.order[SIZES[k - 1] : SIZES[k]].tolist(), s.order[SIZES[k] :].tolist()
            assert set(added) == set(expected[: SIZES[k] - SIZES[k - 1]]), (k, r)
            for part in (added, rest):
                assert [rank[r][i] for i in part] == sorted(rank[r][i] for i in part)
            assert sorted(s.order.tolist()) == list(range(N))
    assert starts == 4
    assert job.progress.selection_presentations == 318 + 301 + 201 + 68  # 952, 902, 602, 202 candidates / 3


def test_hard_and_easy_first_choose_differently_and_differ_from_stratified():
    """On the same networks, hard-first and easy-first share no added pattern at the first enlargement
    (they take opposite ends of the 952 candidates)."""
    subsets = {}
    for kind in ("loss_high", "loss_low", "stratified"):
        cfg = cfg_of(f"schedule.order={kind}", "replicas=2", "schedule.epochs=[3,1,1,1,1]", "engine=torch")
        clock = Clock()
        job = start(resolve(cfg), None, clock)
        for ep in job.prob.plan[:4]:
            run_epoch(job, ep, clock)
        subsets[kind] = [set(s.order[50:100].tolist()) for s in job.prob.samplers]
    for r in range(2):
        assert not subsets["loss_high"][r] & subsets["loss_low"][r]
        assert subsets["loss_high"][r] != subsets["stratified"][r]


def test_loss_orders_are_deterministic_per_seed():
    cfg = cfg_of("schedule.order=loss_high", "replicas=2", "schedule.epochs=[2,2,2,2,2]", "engine=torch")
    assert numbers(train(cfg)) == numbers(train(cfg))


# ------------------------------------------------------------------------------------------- reselect


def _overlaps(X, seeds, k):
    a = reselected_orders(strata(X, 2), seeds, k - 1)[:, : SIZES[k - 1]]
    b = reselected_orders(strata(X, 2), seeds, k)[:, : SIZES[k]]
    return np.array([len(set(x.tolist()) & set(y.tolist())) for x, y in zip(a, b)])


@pytest.mark.parametrize("k", [1, 2, 3])
def test_reselected_subsets_overlap_as_independent_draws(k):
    """Consecutive stages' subsets are independent draws: their mean overlap over 300 seeds is within four
    standard errors of the hypergeometric expectation n_{k-1} n_k / n (a nested order would overlap by
    n_{k-1}), and the spread is no wider than the hypergeometric's (stratification only narrows it)."""
    X = _raw_X(cfg_of())
    a, b = SIZES[k - 1], SIZES[k]
    ov = _overlaps(X, list(range(300)), k)
    mean = a * b / N
    var = b * (a / N) * (1 - a / N) * (N - b) / (N - 1)  # hypergeometric: b draws, a "successes" among N
    assert abs(ov.mean() - mean) < 4 * math.sqrt(var / len(ov)), (ov.mean(), mean)
    assert ov.var(ddof=1) < 1.3 * var
    assert ov.max() < a  # never nested


def test_reselect_in_the_loop_draws_each_stage_afresh_and_ends_with_U():
    cfg = cfg_of("schedule.order=reselect", "replicas=3", "schedule.epochs=[1,1,1,1,1]", "engine=torch")
    clock = Clock()
    job = start(resolve(cfg), None, clock)
    X, seeds = _raw_X(cfg), job.prob.seeds
    for ep in job.prob.plan:
        run_epoch(job, ep, clock)
        want = reselected_orders(strata(X, 2), seeds, ep.stage)[:, : SIZES[ep.stage]]
        got = torch.stack([s.subset() for s in job.prob.samplers])
        assert torch.equal(got, want)
        if ep.stage == 0:  # stage 1 is the stratified order's own A_1
            strat = [priority_order(X, "stratified", generator(s, "subset"), 2)[:50] for s in seeds]
            assert torch.equal(got, torch.stack(strat))
    assert sorted(job.prob.samplers[0].subset().tolist()) == list(range(N))
    assert job.progress.selection_presentations == 0 and job.progress.presentations == sum(SIZES)


def test_reselected_subsets_are_stratified():
    """Each stage's draw is a proportional stratified sample (2 bins per input): every stratum's count
    within 2 of n_k |s| / n, strata counted here from U's own ranges."""
    X = _raw_X(cfg_of())
    A = X.numpy()
    cells = np.minimum(np.floor((A - A.min(0)) / (A.max(0) - A.min(0)) * 2), 1).astype(int)
    sid = np.unique(cells, axis=0, return_inverse=True)[1].ravel()
    share = np.bincount(sid) / N
    for k in range(4):
        for row in reselected_orders(strata(X, 2), [0, 1, 2], k)[:, : SIZES[k]].numpy():
            assert np.abs(np.bincount(sid[row], minlength=len(share)) - SIZES[k] * share).max() <= 2.0


# ------------------------------------------------------------------------------------------------ costs


def test_selection_is_charged_per_candidate_at_the_configured_fraction():
    """loss_high, stages 50/100/400/800/1002, one epoch each, selection_cost 0.25: the enlargements score
    952, 902, 602 and 202 candidates, charged 238, 225.5, 150.5 and 50.5 presentations, rounded up to 238,
    226, 151 and 51 (666 in all) on top of 2352 training presentations; the curve's cost axis carries both."""
    res = train(
        cfg_of(
            "schedule.order=loss_high",
            "schedule.selection_cost=0.25",
            "replicas=2",
            "schedule.epochs=[1,1,1,1,1]",
            "engine=torch",
        )
    )
    assert res["training_presentations"] == 2352
    assert res["selection_presentations"] == 666
    assert res["presentations_done"] == 3018
    assert [c["presentations"] for c in res["curves"]] == [0, 50, 388, 1014, 1965, 3018]
    assert res["selection_cost"] == 0.25 and "select" in res["wall_seconds"]


def test_default_charge_is_a_third_and_fixed_orders_are_charged_nothing():
    """1/3 of 952, 902, 602, 202 candidates: 317.3, 300.7, 200.7, 67.3, charged 318 + 301 + 201 + 68."""
    lh = train(cfg_of("schedule.order=loss_high", "replicas=1", "schedule.epochs=[1,1,1,1,1]"))
    assert lh["selection_presentations"] == 888 and lh["presentations_done"] == 2352 + 888
    # the cost ratio is what was presented and charged over conventional training's 5 epochs of all 1002
    assert lh["cost"]["charged_presentations"] == 888 and lh["schedule"]["cost_ratio"] == (2352 + 888) / 5010
    for kind in ("stratified", "random", "coverage"):
        res = train(cfg_of(f"schedule.order={kind}", "replicas=1", "schedule.epochs=[1,1,1,1,1]"))
        assert res["selection_presentations"] == 0 and res["presentations_done"] == 2352
        assert isinstance(res["presentations_done"], int) and res["cost"]["per_replica"]["charged"] == [0.0]
        assert res["schedule"]["cost_ratio"] == 2352 / 5010 and res["selector"]["order_name"] == kind


def test_charge_rounds_up_to_whole_presentations_without_float_noise():
    assert [selection_charge(c, 1 / 3) for c in (952, 900, 3, 1, 0)] == [318, 300, 1, 1, 0]
    assert [selection_charge(c, f) for c, f in ((10, 0.1), (7, 0.0), (5, 1.0), (3, 0.7))] == [1, 0, 5, 3]


@pytest.mark.parametrize("bad", [-0.1, 1.5])
def test_selection_cost_out_of_range_is_refused(bad):
    with pytest.raises(ConfigError, match=r"schedule\.selection_cost.*\[0, 1\]"):
        resolve(cfg_of(f"schedule.selection_cost={bad}"))
