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
local optimum). Here it is exact (:mod:`selpres.presentation.kmeans`: a dynamic programme over split points of the
sorted distinct scores, in C where it builds, else numpy, the same partition either way; results.json's
``selector.kmeans`` says which ran): deterministic, no seeds, no iterations to converge, and it can only differ from
scikit-learn's where that stops at a worse local optimum. Published edge cases kept: G = 1 is one group; all scores
equal (as every score is on the first epoch) split the draw into ``torch.chunk`` pieces in drawn order; fewer
distinct scores than G give one group each.

Choices the published code leaves to its sampler: annealing from epoch δN (as this package's InfoBatch: the
published sampler anneals from epoch ⌊δN⌋ when δN is not whole; the same when it is) and, with a budget, per
replica by InfoBatch's rule (:class:`~selpres.presentation.pruning._policy.Annealing`); an empty window (no
pattern) presents one random pattern, as published. Replica r's draws come from the stream (seed_r, "pruning",
epoch).
"""

from __future__ import annotations

import logging

import numpy as np
import torch

from selpres.errors import ConfigError
from selpres.presentation.kmeans import kmeans_1d, kmeans_edges, kmeans_implementation
from selpres.presentation.pruning._policy import KEY, Annealing, EpochChoice, Param, ScoredByLoss, pad
from selpres.seeding import generator

__all__ = ["POLICY", "SeTa", "kmeans_1d", "score_groups", "window_of"]  # kmeans_1d: its home is presentation.kmeans

log = logging.getLogger(__name__)


def score_groups(scores: torch.Tensor, groups: int) -> list[torch.Tensor]:
    """Positions in ``scores`` of each group, easiest (lowest centre) first, as the published code groups them."""
    m = len(scores)
    if groups == 1 or not m:  # (nothing drawn: one empty group)
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
        self._arrays: tuple[np.ndarray, ...] | None = None
        if self.groups > 1 and kmeans_implementation() != "native":
            log.warning("SeTa's k-means runs in numpy (slower, the same groups): %s", kmeans_implementation())

    def describe(self) -> dict:
        return {**super().describe(), "kmeans": kmeans_implementation() if self.groups > 1 else None}

    def in_window(self, scores: np.ndarray, epoch: int) -> np.ndarray:
        """Which of one replica's drawn patterns (their scores, in drawn order) the epoch's window holds: the set
        :func:`score_groups` and :func:`window_of` give, found by the window's two score edges (the groups are
        contiguous in sorted order) instead of one pass over the scores per group."""
        m = len(scores)
        if not np.isfinite(scores).all():  # a diverged replica (its results are withheld): its scores say nothing,
            scores = np.zeros_like(scores)  # so it goes on as if they were all equal, and the job with it
        if self.groups == 1 or not m or bool((scores == scores[0]).all()):  # no k-means: as score_groups
            groups = score_groups(torch.from_numpy(scores), self.groups)
            inside = np.zeros(m, dtype=bool)
            for g in window_of(len(groups), epoch, self.window_scale):
                inside[groups[g].numpy()] = True
            return inside
        edges = kmeans_edges(scores, self.groups).tolist()  # group g: the scores in [edges[g-1], edges[g])
        w = window_of(len(edges) + 1, epoch, self.window_scale)
        inside = np.ones(m, dtype=bool) if len(w) else np.zeros(m, dtype=bool)
        if len(w) and w.start > 0:
            inside &= scores >= edges[w.start - 1]
        if len(w) and w.stop <= len(edges):
            inside &= scores < edges[w.stop - 1]
        return inside

    def _scratch(self, n: int, size: int) -> tuple[np.ndarray, ...]:
        """Arrays reused every epoch (a mask over U, the draw's scores, the window's patterns, the mask in the
        epoch's shuffle): fresh ones of 10^5
        entries are mapped in page by page each time, which cost a fifth of an epoch's choice at n = 10^5."""
        if self._arrays is None or len(self._arrays[0]) != n or len(self._arrays[1]) != size:
            self._arrays = (np.empty(n, dtype=bool), np.empty(size), np.empty(size, dtype=np.int64), np.empty(n, bool))
        return self._arrays

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
        scores = self.scores.numpy()  # numpy views throughout: torch's indexing cost more than the k-means here
        size = int(led.n * self.keep)
        mask, drawn_scores, picked, in_order = self._scratch(led.n, size)
        for r, seed in enumerate(led.seeds):
            gen = generator(seed, "pruning", epoch)
            drawn = torch.randperm(led.n, generator=gen)[:size].numpy()
            if not self.annealing(r, epoch, led):
                inside = self.in_window(np.take(scores[r], drawn, out=drawn_scores), epoch)
                drawn = np.compress(inside, drawn, out=picked[: np.count_nonzero(inside)])
            if not len(drawn):  # as published: an empty selection presents one random pattern
                drawn = torch.randint(led.n, (1,), generator=gen).numpy()
            mask[:] = False
            mask[drawn] = True
            shuffled = order[r].numpy()
            kept = torch.from_numpy(shuffled[np.take(mask, shuffled, out=in_order[: len(shuffled)])])  # as shuffled
            led.left_out[r] += led.n - len(kept)
            rows.append(kept)
            counts.append(led.affordable(r, len(kept)))
        return EpochChoice(pad(rows, 0), None, torch.tensor(counts, dtype=torch.int64))


POLICY = SeTa
