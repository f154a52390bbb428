"""``loss_high``: adaptive and nested, hard first: each enlargement adds the patterns outside A_{k-1} the replica's
current network errs most on (``_loss``), charged ``schedule.selection_cost`` per candidate scored."""

from __future__ import annotations

from selpres.presentation.orders._loss import LossOrder


class LossHigh(LossOrder):
    hard = True


ORDER = LossHigh
