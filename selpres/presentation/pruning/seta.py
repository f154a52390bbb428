"""SeTa, "Scale Efficient Training for Large Datasets" (Zhou, Gao & Wang, CVPR 2025; code mrazhou/SeTa, ``seta.py``).

Every pattern's score is its latest training loss (initially 3.0, as InfoBatch's). Each epoch before a share δ of
the epochs (``delta``):

* a random ``int(keep n)`` of all patterns is drawn, keep = 1 - ``prune_ratio``;
* their scores are clustered by 1-D k-means into G = ``groups`` groups, sorted by centre (easiest first);
* the first epoch trains on all the groups; after that a window of ``round(G window_scale)`` groups slides from
  easy to hard, starting at group ``epoch mod (G - window + 1)``;
* the window's patterns are presented shuffled (in the epoch's shuffle of U), with no loss reweighting.

After δ (partial annealing): a fresh random ``int(keep n)`` of all patterns each epoch. The scores of the presented
patterns are their losses in that epoch's training passes (nothing is charged for them); the k-means runs in the
clock's "select" phase, so it is in the job's measured wall time. G = 1 with window 1 is the paper's "Dynamic
Random" control (``configs/schedule/seta_random.yaml``).

**The k-means.** The published code calls scikit-learn's ``KMeans`` (Lloyd's iterations from k-means++ seeds: a
local optimum). Here it is exact: clusters of an optimal 1-D k-means are contiguous in sorted order, so the optimum
is a dynamic programme over split points of the sorted distinct scores (weighted by their multiplicities, so equal
scores share a group), D_k(i) = min_j D_{k-1}(j) + SSE(j, i), SSE from prefix sums. The sum-of-squares cost obeys
the quadrangle inequality, so the leftmost optimal split is monotone in i and each layer is solved by divide and
conquer (Grønlund et al. 2017, "Fast exact k-means, k-medians and Bregman divergence clustering in 1D"): O(G n log n),
vectorised one recursion depth at a time (about G log2 n array passes). Exact, deterministic (no seeds, no
iterations to converge), and no new dependency; it can only differ from scikit-learn's where that stops at a worse
local optimum. Published edge cases kept: G = 1 is one group; all scores equal (as every score is on the first epoch)
split the draw into ``torch.chunk`` pieces in drawn order; fewer distinct scores than G give one group each.

Choices the published code leaves to its sampler: annealing from epoch δN (as this package's InfoBatch: the
published sampler anneals from epoch ⌊δN⌋ when δN is not whole; the same when it is) and, with a budget, per
replica by InfoBatch's rule (:class:`~selpres.presentation.pruning._policy.Annealing`); an empty window (no
pattern) presents one random pattern, as published. Replica r's draws come from the stream (seed_r, "pruning",
epoch).
"""

from __future__ import annotations

import numpy as np
import torch

from selpres.errors import ConfigError
from selpres.presentation.pruning._policy import KEY, Annealing, EpochChoice, Param, ScoredByLoss, pad
from selpres.seeding import generator


def _layer(prev: np.ndarray, prefix: tuple[np.ndarray, ...], k: int, d: int) -> tuple[np.ndarray, np.ndarray]:
    """D_k(i) for i = k..d and its leftmost optimal split j, by divide and conquer over i, one depth at a time."""
    D = np.full(d + 1, np.inf)
    arg = np.zeros(d + 1, dtype=np.int64)
    tasks = np.array([[k, d, k - 1, d - 1]], dtype=np.int64)  # rows: i_lo, i_hi, j_lo, j_hi
    while len(tasks):
        i_lo, i_hi, j_lo, j_hi = tasks.T
        mid = (i_lo + i_hi) // 2
        hi = np.minimum(j_hi, mid - 1)
        lens = hi - j_lo + 1  # >= 1: j_lo <= i_lo - 1 <= mid - 1 throughout
        starts = np.concatenate(([0], np.cumsum(lens)[:-1]))
        j = np.repeat(j_lo - starts, lens) + np.arange(int(lens.sum()))  # each task's candidate splits
        W, S, Q = prefix  # the SSE of distinct values j..mid-1: (Q - S^2 / W) over that range
        ws, ss = np.repeat(W[mid], lens) - W[j], np.repeat(S[mid], lens) - S[j]
        vals = prev[j] + ((np.repeat(Q[mid], lens) - Q[j]) - ss * ss / ws)
        best = np.minimum.reduceat(vals, starts)
        first = np.minimum.reduceat(np.where(vals == np.repeat(best, lens), np.arange(len(vals)), len(vals)), starts)
        opt = j[first]
        D[mid], arg[mid] = best, opt
        left = np.stack([i_lo, mid - 1, j_lo, opt], 1)[mid - 1 >= i_lo]
        right = np.stack([mid + 1, i_hi, opt, j_hi], 1)[mid + 1 <= i_hi]
        tasks = np.concatenate([left, right])
    return D, arg


def kmeans_1d(values: np.ndarray, groups: int) -> np.ndarray:
    """An optimal (least within-group sum of squares) partition of ``values`` into at most ``groups`` groups:
    each value's group index, 0 = the lowest centre. Groups are contiguous in sorted order, equal values share one,
    and there are min(groups, number of distinct values) of them."""
    v, inverse, w = np.unique(np.asarray(values, dtype=np.float64), return_inverse=True, return_counts=True)
    d = len(v)
    G = min(groups, d)
    x = v - v.mean()  # centred: the prefix sums lose less to cancellation
    W = np.concatenate(([0.0], np.cumsum(w)))
    S = np.concatenate(([0.0], np.cumsum(w * x)))
    Q = np.concatenate(([0.0], np.cumsum(w * x * x)))

    D = np.full(d + 1, np.inf)
    D[1:] = Q[1:] - S[1:] ** 2 / W[1:]  # one group: the SSE of the distinct values 0..i-1
    args = []
    for k in range(2, G + 1):
        D, arg = _layer(D, (W, S, Q), k, d)
        args.append(arg)
    bounds, end = [d], d  # backtrack the split points from the last group
    for arg in reversed(args):
        end = int(arg[end])
        bounds.append(end)
    starts = np.array([0, *sorted(bounds[1:])], dtype=np.int64)  # each group's first distinct value
    group_of_distinct = np.searchsorted(starts, np.arange(d), side="right") - 1
    return group_of_distinct[inverse.reshape(-1)]


def score_groups(scores: torch.Tensor, groups: int) -> list[torch.Tensor]:
    """Positions in ``scores`` of each group, easiest (lowest centre) first, as the published code groups them."""
    m = len(scores)
    if groups == 1:
        return [torch.arange(m)]
    if m and bool((scores == scores[0]).all()):  # one value: no clustering to do, chunks in drawn order
        return list(torch.chunk(torch.arange(m), groups))
    label = torch.from_numpy(kmeans_1d(scores.numpy(), groups))
    return [torch.nonzero(label == g).flatten() for g in range(int(label.max()) + 1)]


def window_of(n_groups: int, epoch: int, window_scale: float) -> range:
    """The groups presented in a pruned epoch: all at epoch 0, then round(G window_scale) of them from group
    epoch mod (G - window + 1) (sliding easy to hard)."""
    if epoch == 0:
        return range(n_groups)
    window = round(n_groups * window_scale)
    start = epoch % (n_groups - window + 1)
    return range(start, start + window)


class SeTa(ScoredByLoss):
    PARAMS = {
        "prune_ratio": Param(float, lambda v: 0 <= v <= 0.9, "a share in [0, 0.9] (the published code keeps >= 10%)"),
        "groups": Param(int, lambda v: v >= 1, "a whole number of k-means groups >= 1 (Zhou et al.: 5)"),
        "window_scale": Param(float, lambda v: 0 < v <= 1, "a share of the groups in (0, 1] (Zhou et al.: 0.9)"),
        "delta": Param(float, lambda v: 0 < v <= 1, "a share of the epochs in (0, 1] (Zhou et al.: 0.875)"),
    }

    @classmethod
    def check(cls, params: dict, *, budget: int | None, selection_cost: float) -> dict:
        out = super().check(params, budget=budget, selection_cost=selection_cost)
        if round(out["groups"] * out["window_scale"]) < 1:
            allowed = f"a share with round(groups * window_scale) >= 1 window group (groups = {out['groups']})"
            raise ConfigError(f"{KEY}.window_scale", out["window_scale"], allowed)
        return out

    def __init__(self, params: dict, ledger):
        super().__init__(params, ledger)
        self.keep = 1.0 - params["prune_ratio"]
        self.groups, self.window_scale = params["groups"], params["window_scale"]
        self.annealing = Annealing(params["delta"], len(ledger.seeds))

    @classmethod
    def epoch_share(cls, params: dict, selection_cost: float) -> float:
        # the window's share of the draw, halved: k-means groups need not be of equal size (a shorter epoch than
        # this still stops at the budget if the plan has epochs left; the ledger records what ran)
        keep = 1.0 - float(params["prune_ratio"])
        window = round(params["groups"] * params["window_scale"])
        return keep * min(window / params["groups"], 1.0) / 2

    def choose(self, epoch: int, order: torch.Tensor, losses: torch.Tensor | None) -> EpochChoice:
        led = self.ledger
        rows, counts = [], []
        for r, seed in enumerate(led.seeds):
            gen = generator(seed, "pruning", epoch)
            drawn = torch.randperm(led.n, generator=gen)[: int(led.n * self.keep)]
            if not self.annealing(r, epoch, led):
                groups = score_groups(self.scores[r, drawn], self.groups)
                window = [groups[g] for g in window_of(len(groups), epoch, self.window_scale)]
                drawn = drawn[torch.cat(window)] if window else drawn[:0]
            if not len(drawn):  # as published: an empty selection presents one random pattern
                drawn = torch.randint(led.n, (1,), generator=gen)
            mask = torch.zeros(led.n, dtype=torch.bool)
            mask[drawn] = True
            kept = order[r][mask[order[r]]]  # shuffled: in the epoch's shuffle of U
            led.left_out[r] += led.n - len(kept)
            rows.append(kept)
            counts.append(led.affordable(r, len(kept)))
        return EpochChoice(pad(rows, 0), None, torch.tensor(counts, dtype=torch.int64))


POLICY = SeTa
