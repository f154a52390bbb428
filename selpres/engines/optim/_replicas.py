"""One ``torch.optim`` optimizer stepping R replicas' stacked weights as R separate optimizers would.

The mini-batch engine keeps every replica's weights in one row of a flat ``[R, P]`` tensor. An elementwise rule
stepped on it is R separate optimizers (bit for bit, ``tests/test_optim.py``), in one call of a dozen tensor
operations, as long as every replica steps with the same learning rate and step count. Data pruning breaks
that: a replica with nothing left in a mini-batch must not step (Adam's moments would still move it, and its
step count must not advance), and replicas spend their budgets at different rates, so their cosine learning
rates differ. At the first such step the optimizer is split, losslessly, into one parameter group per replica
(each row a leaf view into the same storage, its state the row of the stacked state): an inactive replica's row
then has no gradient, so torch leaves its weights and state alone, and each group has its own ``lr``.
"""

from __future__ import annotations

from collections.abc import Callable

import torch


class ReplicaSteps:
    """``make(params)`` -> a torch optimizer; ``flat`` [R, P] (its ``.grad`` set by the engine)."""

    def __init__(self, make: Callable[[list], torch.optim.Optimizer], flat: torch.Tensor):
        self.make, self.flat = make, flat
        self.opt = make([flat])
        self.rows: list[torch.Tensor] | None = None  # one leaf view per replica, once split

    @torch.no_grad()
    def step(self, lr: torch.Tensor, active: torch.Tensor | None = None) -> None:
        """One step: replica r at learning rate ``lr[r]``, only where ``active[r]`` (None: every replica)."""
        if self.rows is None and active is None and bool((lr == lr[0]).all()):
            self.opt.param_groups[0]["lr"] = float(lr[0])
            self.opt.step()
            return
        if self.rows is None:
            self._split()
        for r, (row, group) in enumerate(zip(self.rows, self.opt.param_groups)):
            row.grad = self.flat.grad[r] if active is None or bool(active[r]) else None
            group["lr"] = float(lr[r])
        self.opt.step()

    def _split(self) -> None:
        R = self.flat.shape[0]
        stacked = self.opt.state.get(self.flat, {})
        self.rows = [self.flat[r].detach() for r in range(R)]  # leaves sharing the flat tensor's storage
        opt = self.make([{"params": [row]} for row in self.rows])
        for r, row in enumerate(self.rows):
            if stacked:
                opt.state[row] = {k: self._row(k, v, r) for k, v in stacked.items()}
        self.opt = opt

    def _row(self, key: str, v, r: int):
        if not isinstance(v, torch.Tensor):
            return v
        if v.dim() == 0:
            return v.clone()  # a step count: the same for every replica until the split
        if v.shape == self.flat.shape:
            return v[r].clone()
        raise ValueError(
            f"optimizer state {key!r} of shape {tuple(v.shape)} is not per weight: not an elementwise rule"
        )

    def state_dict(self) -> dict:
        return {"split": self.rows is not None, "optimizer": self.opt.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        if "split" not in state:
            raise ValueError("a mini-batch optimizer state from before the optimizers became torch.optim classes")
        if state["split"] and self.rows is None:
            self._split()
        self.opt.load_state_dict(state["optimizer"])
