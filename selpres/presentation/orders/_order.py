"""The interface every order meets: a priority order of U per replica, and what choosing costs.

An order fixed before training implements :meth:`Order.orders` only: every prefix of its permutation of U is a
training set A_i. A stage-wise order (``_stagewise.StagewiseOrder``) also chooses A_k at the start of stage k and
says how many candidates it scores there; the charge for them is the same rule for every order
(:func:`selection_charge`), so an order states counts, never costs.
"""

from __future__ import annotations

import math

import torch


class Order:
    """A priority order of U. ``strata_bins`` is ``schedule.strata_bins`` (orders that stratify U read it)."""

    stagewise = False  # True: A_k is chosen at each stage start from the network (StagewiseOrder)

    def __init__(self, strata_bins: int = 2):
        self.strata_bins = strata_bins

    def orders(self, X: torch.Tensor, gens: list[torch.Generator]) -> list[torch.Tensor]:
        """One permutation of U's indices (X: [n, inputs], raw exemplar inputs) per generator (one per replica),
        a deterministic function of (X, the generator's seed); each must equal what that generator gives alone.
        A stage-wise order's are the orders the job starts from."""
        raise NotImplementedError

    def candidates(self, kept: int, n: int) -> int:
        """Patterns scored by a forward pass when A_k is chosen after a stage of ``kept`` patterns (of n): each
        is charged ``schedule.selection_cost`` of a presentation. 0: the order chooses without the network."""
        return 0

    def planned_charge(self, sizes: list[int], fraction: float) -> int:
        """Presentations a schedule of stage ``sizes`` (counts, the last = n) is charged per replica for choosing:
        known before training, so a run's total cost can be matched by a one-stage partner."""
        return sum(selection_charge(self.candidates(kept, sizes[-1]), fraction) for kept in sizes[:-1])


def selection_charge(candidates: int, fraction: float) -> int:
    """Presentations charged per replica for scoring ``candidates`` patterns by a forward pass: candidates x
    fraction, rounded up to a whole presentation (presentations are counts; never under-charged), after
    rounding off float noise (952 x 1/3 -> 318, 900 x 1/3 -> 300)."""
    return math.ceil(round(candidates * fraction, 9))
