"""Mini-batch training of R replicas with today's units and optimizers: ReLU/SiLU/tanh nets, Adam, AdamW, SGD, ...

The online engines (:mod:`selpres.engines.online`) run the paper's network - sigmoid units, SGD with
momentum at a constant rate - and the native kernel runs nothing else. :class:`MiniBatchEngine` runs what
they cannot, replica-batched in eager torch with a hand-written backward (checked against autograd on
:class:`selpres.engines.model.BPN`, ``tests/test_minibatch.py``):

* ``model.activation``: sigmoid, tanh, relu, silu or a user's own hidden units (:mod:`selpres.engines.activations`;
  linear output unless sigmoid);
* ``optim._target_``: any elementwise ``torch.optim`` optimizer (sgd, adam, adamw, a user's own) on mini-batches of
  ``optim.batch_size`` patterns, stepped on the replicas' stacked weights: R separate optimizers
  (:class:`selpres.engines.optim._replicas.ReplicaSteps`);
* ``optim.lr_schedule``: ``constant`` or ``cosine``: lr · ½(1 + cos(π c / C)) where c is the replica's cost
  so far (presentations, forward passes charged for choosing included) and C the run's own budget, so a
  run scheduled for a smaller budget decays to zero at its own end (a compute-matched run is one scheduled
  for that budget, not a prefix of a longer run); ``cosine_epochs``: the same curve on the epochs' clock,
  c = e n at the start of epoch e whatever the epochs before presented (then advanced by the presentations),
  C = N n: a pruned run's rate reaches its end as SeTa's authors re-position their schedule every epoch
  (one stage of all of U for N epochs only: :func:`check_epoch_clock`);
* per-pattern weights and per-replica pattern counts (``train_epoch(..., weights, counts)``), which the
  data-pruning schedules of :mod:`selpres.presentation.pruning` need: replica r presents the first
  ``counts[r]`` entries of ``order[r]`` and a mini-batch's loss is the mean of ``weights · loss`` over its
  patterns (InfoBatch's rescaled loss); a replica with nothing left in a mini-batch does not step. (The
  online engines do the same for the paper's network, so pruning jobs with sigmoid units and SGD at a
  constant rate run there, on the native kernel: ``selpres.engines.factory.mode_for``.)

Loss per pattern: ``mse`` over the outputs (``reduction=mean``: the online engines' loss; ``sum``:
Rumelhart's ½Σe², for configs written for batch mode). ``last_losses`` holds every presented pattern's loss
before its update (InfoBatch's scores come from there, at no extra cost).
"""

from __future__ import annotations

import copy
import math

import torch

from selpres.engines.activations import activation as units
from selpres.engines.inputs import check_inputs, check_patterns, pruned_epoch_args, pruned_mean
from selpres.engines.model import forward_replicas
from selpres.engines.online import ScoredByPredict
from selpres.engines.optim import make_optimizer, with_defaults
from selpres.engines.optim._replicas import ReplicaSteps
from selpres.errors import ConfigError

LR_SCHEDULES = ("constant", "cosine", "cosine_epochs")
EPOCH_CLOCK = "cosine_epochs"  # the cosine on the epochs' clock (SeTa's authors'), not the cost's


def lr_factor(kind: str, spent: torch.Tensor, horizon: float) -> torch.Tensor:
    """The learning rate's factor [R] at clock ``spent`` [R] of a run whose clock ends at ``horizon``."""
    if kind == "constant":
        return torch.ones_like(spent)
    frac = (spent / max(horizon, 1e-300)).clamp(0.0, 1.0)
    return 0.5 * (1.0 + torch.cos(math.pi * frac))


def epoch_clock(kind: str, spent: torch.Tensor, epochs: int, n: int) -> None:
    """At an epoch's start, the rate's clock ``spent`` [R] (in place): under :data:`EPOCH_CLOCK` ``epochs`` full
    epochs of the ``n`` patterns of U, whatever they presented; under the other schedules as the caller set it."""
    if kind == EPOCH_CLOCK:
        spent.fill_(float(epochs * n))


def check_epoch_clock(kind: str, sizes: list | None, epochs: list | None, budget: int | None) -> None:
    """A ConfigError naming ``optim.lr_schedule`` when a schedule (its ``sizes``, ``epochs`` and ``budget`` as
    written) cannot run on the epochs' clock: its horizon N n needs one stage of all of U for a known N epochs (a
    budget's epochs are not known beforehand, a stage of a subset presents fewer than n an epoch)."""
    all_of_u = list(sizes or []) == [1.0] and isinstance(sizes[0], float)  # (an int 1 is one pattern)
    if kind != EPOCH_CLOCK or (all_of_u and epochs is not None and len(epochs) == 1 and budget is None):
        return
    raise ConfigError(
        "optim.lr_schedule",
        kind,
        "constant or cosine: cosine_epochs positions the rate at e / N at the start of epoch e of N, which needs "
        "one stage of all of U for N epochs (schedule.sizes=[1.0], schedule.epochs=[N], no schedule.budget); this "
        f"schedule has sizes {sizes}, epochs {epochs}, budget {budget}",
    )


class MiniBatchEngine(ScoredByPredict):
    """R replicas, mini-batches of ``batch_size``, the optimizer ``optimizer`` (a built-in name or an import path)
    with keyword arguments ``hparams`` (``lr`` is the schedule's peak), ``activation`` hidden units."""

    name = "minibatch"

    @classmethod
    def from_spec(cls, spec, params):
        """An engine of ``spec`` (:class:`selpres.engines.factory.EngineSpec`): the optimizer's keys with its
        defaults for the unset ones (as the native kernel fills them), the units, rate schedule and reduction."""
        hp = with_defaults(spec.optimizer, spec.hparams)
        args = (spec.batch_size, spec.activation, spec.lr_schedule, spec.horizon, spec.reduction)
        return cls(spec.sizes, params, spec.optimizer, hp, *args)

    def __init__(
        self,
        sizes,
        params,
        optimizer: str,
        hparams: dict,
        batch_size: int,
        activation: str = "sigmoid",
        lr_schedule: str = "constant",
        horizon: float = 1.0,
        reduction: str = "mean",
    ):
        self.sizes = tuple(int(s) for s in sizes)
        if len(params) != 2 * (len(self.sizes) - 1):
            raise ValueError(f"{len(params)} parameter tensors for topology {self.sizes}")
        if lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"lr_schedule {lr_schedule!r}: one of {LR_SCHEDULES}")
        self.optimizer, self.batch_size, self.activation = optimizer, int(batch_size), activation
        self.act = units(activation)  # forward(z), prime(z, a): selpres.engines.activations
        self.lr_schedule, self.horizon, self.reduction = lr_schedule, float(horizon), reduction
        self.fallback_reason: str | None = None  # set by selpres.engines.factory when it stands in for the kernel
        self.R = params[0].shape[0]
        # every replica's weights in one row of a flat [R, P] tensor (and its gradient likewise): the optimizer
        # steps it in a dozen ops; self.p / self._g are per-layer views into them
        self.shapes = [tuple(t.shape[1:]) for t in params]
        self.flat = torch.cat([t.detach().to(torch.float64).reshape(self.R, -1) for t in params], dim=1)
        self.flat.grad = torch.zeros_like(self.flat)
        self.p, self._g = self._views(self.flat), self._views(self.flat.grad)
        h = {k: v for k, v in hparams.items() if v is not None}
        self.opt = ReplicaSteps(lambda params: make_optimizer(optimizer, params, h), self.flat)
        self.lr = float(self.opt.opt.param_groups[0]["lr"])  # the schedule's peak: optim.lr, or the class's default
        self.spent = torch.zeros(self.R, dtype=torch.float64)  # each replica's cost so far (the lr schedule's clock)
        self.epochs = 0  # epochs trained (the clock of cosine_epochs)
        self.last_losses = torch.empty(self.R, 0, dtype=torch.float64)

    def _views(self, flat: torch.Tensor) -> list[torch.Tensor]:
        out, k = [], 0
        for s in self.shapes:
            n = int(torch.Size(s).numel())
            out.append(flat[:, k : k + n].view(self.R, *s))
            k += n
        return out

    @torch.no_grad()
    def train_epoch(self, X, Y, order, weights=None, counts=None, spent=None):
        """Mini-batches over ``order[r, :counts[r]]``; returns the [R] mean pre-update pattern loss. ``spent``: each
        replica's cost so far, the rate schedule's clock (None: the engine's own count, e.g. from a checkpoint)."""
        check_inputs(self.sizes, X, Y, order, self.R)
        if spent is not None:
            self.spent.copy_(torch.as_tensor(spent, dtype=torch.float64).expand_as(self.spent))
        epoch_clock(self.lr_schedule, self.spent, self.epochs, X.shape[0])
        self.epochs += 1
        R, m = order.shape
        X, Y = X.to(torch.float64), Y.to(torch.float64)
        weights, counts = pruned_epoch_args(order, weights, counts)
        counts = torch.full((R,), m, dtype=torch.int64) if counts is None else counts
        nout, B, act = self.sizes[-1], self.batch_size, self.act
        squash = getattr(act, "SIGMOID_OUTPUT", False)  # the paper's net: a sigmoid output layer
        Ws, bs = self.p[0::2], self.p[1::2]
        self.last_losses = torch.full((R, m), float("nan"), dtype=torch.float64)
        total = torch.zeros(R, dtype=torch.float64)
        last = len(Ws) - 1
        for start in range(0, m, B):
            nb = (counts - start).clamp(0, B)  # [R] patterns of this mini-batch per replica
            idx = order[:, start : start + B]
            width = idx.shape[1]
            full = bool((nb == width).all())  # the usual case: every replica presents a whole mini-batch
            active = None if full else nb > 0
            if active is not None and not bool(active.any()):
                break
            valid = torch.ones(R, width, dtype=torch.float64)
            if not full:
                valid = (torch.arange(width).unsqueeze(0) < nb.unsqueeze(1)).to(torch.float64)  # [R, b]
                idx = torch.where(valid.bool(), idx, idx[:, :1])  # padding rows read a real pattern, weighted 0
            zs, acts = [], [X[idx]]
            for k, (W, b) in enumerate(zip(Ws, bs)):
                z = torch.baddbmm(b.unsqueeze(1), acts[-1], W.transpose(1, 2))
                zs.append(z)
                acts.append(torch.sigmoid(z) if k == last and squash else (z if k == last else act.forward(z)))
            diff = acts[-1] - Y[idx]
            loss_p = diff.square().mean(-1)  # [R, b] per-pattern mse
            if not full:
                loss_p = loss_p * valid  # 0 on padding
            self.last_losses[:, start : start + width] = loss_p if full else torch.where(valid.bool(), loss_p, math.nan)
            total += loss_p.sum(1)
            w = valid if weights is None else valid * weights[:, start : start + width]
            if self.reduction == "mean":
                scale = (2.0 / (nb.clamp(min=1).to(torch.float64) * nout)).unsqueeze(1) * w
            else:
                scale = w
            delta = diff * scale.unsqueeze(2)  # dL/d(output)
            if squash:
                delta = delta * acts[-1] * (1 - acts[-1])
            for layer in range(last, -1, -1):
                a_prev = acts[layer]
                self._g[2 * layer].copy_(torch.bmm(delta.transpose(1, 2), a_prev))
                self._g[2 * layer + 1].copy_(delta.sum(dim=1))
                if layer:
                    delta = torch.bmm(delta, Ws[layer]) * act.prime(zs[layer - 1], a_prev)
            lr = self.lr * lr_factor(self.lr_schedule, self.spent, self.horizon)
            self.opt.step(lr=lr, active=active)
            self.spent += nb.to(torch.float64)
        return pruned_mean(total, counts)

    def predict(self, X):
        return forward_replicas(self.p, check_patterns(self.sizes, X), self.activation)

    def finite(self):
        return torch.isfinite(self.flat).all(1)

    def params(self):
        return [t.clone().contiguous() for t in self.p]

    def state_dict(self):
        opt = copy.deepcopy(self.opt.state_dict())
        return {"params": self.params(), "optimizer": opt, "spent": self.spent.clone(), "epochs": self.epochs}

    def load_state_dict(self, state):
        with torch.no_grad():
            for p, src in zip(self.p, state["params"]):
                p.copy_(src)  # views: into self.flat
        self.opt.load_state_dict(copy.deepcopy(state["optimizer"]))
        self.spent = state["spent"].clone()
        self.epochs = int(state.get("epochs", 0))  # (older checkpoints: their clock was the cost's)
