"""SeTa (Zhou, Gao & Wang, CVPR 2025) against independent derivations: the sliding window worked out by hand, the
k-means against brute force, the annealing share, and its Dynamic Random control at prune_ratio 0 = conventional
training."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from selpres.presentation.pruning.seta import SeTa, kmeans_1d, score_groups
from selpres.presentation.selector import Ledger

from conftest import cfg_of


def _seta(n, *, prune_ratio=0.0, groups=5, window_scale=0.9, delta=1.0, epochs=100, seeds=(3,), budget=None):
    params = {"prune_ratio": prune_ratio, "groups": groups, "window_scale": window_scale, "delta": delta}
    ledger = Ledger(n, list(seeds), budget, None if budget else epochs, 1 / 3)
    return SeTa(SeTa.check(params, budget=budget, selection_cost=1 / 3), ledger)


def _presented(pr: SeTa, epoch: int, order: torch.Tensor) -> list[set[int]]:
    c = pr.choose(epoch, order, None)
    return [set(c.order[r, : int(c.counts[r])].tolist()) for r in range(len(c.counts))]


# the window over the groups (0 = easiest) by hand: round(G * window_scale) groups from epoch mod (G - window + 1);
# Python's round is half to even, as the published code's: round(4.5) = 4, round(2.5) = 2, round(1.5) = 2
BY_HAND = {
    (5, 0.9): [[0, 1, 2, 3, 4], [1, 2, 3, 4], [0, 1, 2, 3], [1, 2, 3, 4], [0, 1, 2, 3]],  # window 4, starts 0, 1
    (4, 0.5): [[0, 1, 2, 3], [1, 2], [2, 3], [0, 1], [1, 2], [2, 3]],  # window 2, starts e mod 3
    (5, 0.5): [[0, 1, 2, 3, 4], [1, 2], [2, 3], [3, 4], [0, 1], [1, 2]],  # window round(2.5) = 2, starts e mod 4
    (3, 0.5): [[0, 1, 2], [1, 2], [0, 1], [1, 2]],  # window round(1.5) = 2, starts e mod 2
    (3, 0.2): [[0, 1, 2], [1], [2], [0], [1]],  # window round(0.6) = 1, starts e mod 3
    (1, 1.0): [[0], [0], [0]],  # Dynamic Random: one group, always presented
}


@pytest.mark.parametrize("G, scale", list(BY_HAND))
def test_the_window_slides_from_easy_to_hard_as_worked_out_by_hand(G, scale):
    # G clusters of different sizes far apart: cluster g holds the patterns scored near 10 g (easiest: g = 0)
    sizes = [3, 5, 2, 4, 6][:G]
    cluster = torch.cat([torch.full((s,), g) for g, s in enumerate(sizes)])
    n = len(cluster)
    pr = _seta(n, groups=G, window_scale=scale)
    noise = torch.rand(n, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    pr.scores[0] = 10.0 * cluster + noise
    order = torch.randperm(n, generator=torch.Generator().manual_seed(1)).unsqueeze(0)
    for epoch, window in enumerate(BY_HAND[(G, scale)]):
        want = {i for i in range(n) if int(cluster[i]) in window}
        assert _presented(pr, epoch, order) == [want], epoch
    c = pr.choose(1, order, None)
    assert c.weights is None  # no loss reweighting
    assert c.order[0, : int(c.counts[0])].tolist() == [
        i for i in order[0].tolist() if int(cluster[i]) in BY_HAND[(G, scale)][1]
    ]


def test_a_replica_whose_scores_are_not_finite_goes_on_as_if_they_were_equal():
    # a diverged replica's losses are NaN or inf: the k-means cannot order them (it raised IndexError before); its
    # epoch is the one of equal scores, the groups torch.chunk pieces in drawn order, and the other replica's is its own
    n = 20
    pr, alone = _seta(n, seeds=(3, 4)), _seta(n, seeds=(4,))
    pr.scores[0] = torch.tensor([float("nan"), float("inf")] + [1.0] * (n - 2), dtype=torch.float64)
    pr.scores[1] = alone.scores[0] = torch.arange(n, dtype=torch.float64)
    equal = _seta(n, seeds=(3,))  # every score 3.0, as on the first epoch
    order = torch.stack([torch.randperm(n, generator=torch.Generator().manual_seed(s)) for s in (1, 2)])
    for epoch in range(3):
        got = _presented(pr, epoch, order)
        assert got[0] == _presented(equal, epoch, order[:1])[0]
        assert got[1] == _presented(alone, epoch, order[1:])[0]


def _sse(x: np.ndarray, labels: np.ndarray) -> float:
    return float(sum(((x[labels == g] - x[labels == g].mean()) ** 2).sum() for g in np.unique(labels)))


def test_the_k_means_is_optimal_against_brute_force_over_every_labelling():
    """Every assignment of up to 7 values to G labels (not only contiguous ones): none has a smaller sum of
    squares than kmeans_1d's, so contiguity costs nothing and the dynamic programme finds the optimum."""
    rng = np.random.default_rng(0)
    for t in range(150):
        n, G = int(rng.integers(1, 8)), int(rng.integers(1, 4))
        x = np.round(rng.random(n) * 3, 1) if t % 3 == 0 else rng.random(n)  # ties too
        got = kmeans_1d(x, G)
        distinct = len(np.unique(x))
        assert len(np.unique(got)) == min(G, distinct)
        best = min(_sse(x, np.array(lab)) for lab in itertools.product(range(G), repeat=n))
        assert _sse(x, got) == pytest.approx(best, abs=1e-12), (x, G)
    # a local optimum Lloyd's iterations can stop at is not what it returns: [0, 1, 2, 10, 11, 12, 30] into 2 groups
    x = np.array([0.0, 1, 2, 10, 11, 12, 30])
    assert kmeans_1d(x, 2).tolist() == [0, 0, 0, 0, 0, 0, 1]


def test_groups_are_contiguous_in_sorted_order_with_increasing_centres():
    g = torch.Generator().manual_seed(5)
    scores = torch.cat([torch.rand(3000, generator=g, dtype=torch.float64) ** 3, torch.full((40,), 3.0)])
    groups = score_groups(scores, 5)
    assert len(groups) == 5 and sorted(torch.cat(groups).tolist()) == list(range(len(scores)))
    for a, b in zip(groups, groups[1:]):
        assert scores[a].max() < scores[b].min()  # contiguous: every score of a group below the next group's
        assert scores[a].mean() < scores[b].mean()
    assert set(groups[-1].tolist()) == set(range(3000, 3040))  # the never-presented patterns (score 3.0): hardest
    # all scores equal (the first epoch): the draw in chunks, in drawn order, as published
    same = score_groups(torch.full((11,), 3.0, dtype=torch.float64), 5)
    assert [x.tolist() for x in same] == [[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10]]


def test_after_delta_a_fresh_random_share_each_epoch():
    n, E, delta, r = 200, 10, 0.6, 0.25
    pr = _seta(n, prune_ratio=r, groups=5, window_scale=0.4, delta=delta, epochs=E, seeds=(0, 1))
    pr.scores[:] = torch.rand(2, n, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    order = torch.stack([torch.randperm(n, generator=torch.Generator().manual_seed(s)) for s in (7, 8)])
    seen = []
    for epoch in range(E):
        sets = _presented(pr, epoch, order)
        if epoch >= delta * E:  # epochs 6..9: int((1 - r) n) = 150 patterns, a new draw each epoch
            assert [len(s) for s in sets] == [150, 150]
            seen.append(frozenset(sets[0]))
        elif epoch > 0:  # a window of round(5 * 0.4) = 2 of the 5 groups of the 150 drawn
            assert all(len(s) < 150 for s in sets)
    assert len(set(seen)) == len(seen)
    assert pr.ledger.left_out.tolist()[0] > 0


def test_prune_ratio_0_with_one_group_is_conventional_training():
    """The same patterns every epoch, in the epoch's shuffle: the numbers of conventional training (random order)."""
    n = 30
    pr = _seta(n, groups=1, window_scale=1.0)
    order = torch.randperm(n, generator=torch.Generator().manual_seed(4)).unsqueeze(0)
    for epoch in range(4):
        c = pr.choose(epoch, order, None)
        assert c.order[0].tolist() == order[0].tolist() and int(c.counts[0]) == n and c.weights is None
    from selpres.run.train import train

    common = ("schedule.epochs=[3]", "replicas=2", "schedule.order=random")
    plain = train(cfg_of("schedule=conventional", *common))
    seta = train(cfg_of("schedule=seta_random", "schedule.pruning.prune_ratio=0", *common))
    assert seta["cost"]["per_replica"]["left_out"] == [0.0, 0.0]
    assert seta["replica_results"] == plain["replica_results"]
    assert seta["summary"] == plain["summary"]


def test_a_budget_run_stops_at_it_and_is_charged_like_infobatch():
    from selpres.run.train import train

    res = train(cfg_of("schedule=seta", "schedule.epochs=null", "schedule.budget=5000", "replicas=2"))
    pr = res["cost"]["per_replica"]
    assert res["selector"]["class"] == "selpres.presentation.pruning.seta.SeTa"
    for cost, trained in zip(pr["spent"], pr["trained"]):
        assert 5000 - 1 < cost <= 5000 + 1e-9 and cost == trained  # choosing is not charged: scores are free
    assert pr["charged"] == [0.0, 0.0] and all(x > 0 for x in pr["left_out"])


def test_a_sweep_over_seta_and_its_dynamic_random_control_from_the_command_line(tmp_path):
    import json

    from conftest import run_python

    p = run_python(
        "train.py",
        "-m",
        "schedule=seta,seta_random",
        "schedule.epochs=[2]",
        "replicas=2",
        f"hydra.sweep.dir={tmp_path}",
    )
    assert p.returncode == 0, p.stderr[-2000:]
    runs = {
        json.loads(f.read_text())["config"]["schedule"]["name"]: json.loads(f.read_text())
        for f in tmp_path.rglob("results.json")
    }
    assert set(runs) == {"seta", "seta_random"}
    for res in runs.values():
        assert res["status"] == "complete" and res["selector"]["class"] == "selpres.presentation.pruning.seta.SeTa"
    assert runs["seta_random"]["selector"]["groups"] == 1
