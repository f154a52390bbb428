"""Mini-batch training on the native kernel: what :class:`selpres.engines.minibatch.MiniBatchEngine` computes, in C.

The torch mini-batch engine steps R replicas in eager torch, a few dozen tensor operations a mini-batch, each
~10 us of dispatch at these sizes, so it is bound by the interpreter, not the arithmetic. The kernel
(``selpres/native/kernels/minibatch.c``) runs a whole epoch in one call: ReLU / SiLU / tanh / sigmoid hidden
units (linear output, or sigmoid with sigmoid units, as the torch engine), SGD with momentum, Adam or AdamW
with each replica's own step count and rate, a constant or cosine rate over the run's budget, ``mean`` or
``sum`` reduction, and the pruned epochs of :mod:`selpres.presentation.pruning` (per-replica counts, a weight
per presented pattern, each pattern's loss in ``last_losses``). Its numbers agree with the torch engine and
with one ``BPN`` + one ``torch.optim`` optimizer per replica to rounding (tests/test_native_minibatch.py).

It is the ``(minibatch, native)`` engine of :mod:`selpres.engines.factory`, whose ``build_engine`` chooses between it
and the torch engine (it raises :class:`selpres.native.KernelUnavailable` where it cannot run, naming what it
lacks). Evaluation (``predict``, ``squared_errors``) runs the torch engine's forward pass on the unpacked weights, so
both engines score alike.

It shares no state with the torch engine: weights and the optimizer's moments live packed for the kernel, 4
replicas per vector as the online native engine packs them (its ``_pack``/``_unpack``/``_lanes`` are used as they
are); like every engine it answers the one epoch call, the rate's clock ``spent`` included.
"""

from __future__ import annotations

import numpy as np
import torch

from selpres.engines.inputs import check_inputs, check_patterns, pruned_epoch_args, pruned_mean
from selpres.engines.minibatch import LR_SCHEDULES, epoch_clock
from selpres.engines.model import forward_replicas
from selpres.engines.online import NativeEngine, ScoredByPredict, _default_threads
from selpres.engines.optim import with_defaults
from selpres.native import KernelUnavailable
from selpres.native.staging import stage

NAME = "minibatch-native"
# the optimizer keys the kernel reads, with ReplicaOptimizer's defaults for the ones a config leaves unset
HPARAM_DEFAULTS = {"momentum": 0.0, "beta1": 0.9, "beta2": 0.999, "eps": 1e-8, "weight_decay": 0.0}
REDUCTIONS = ("mean", "sum")


def native_reason(rule: str, activation: str, lr_schedule: str, reduction: str, hparams: dict) -> str | None:
    """Why the kernel cannot run this job (an optimizer, unit, schedule or key it does not have), or None."""
    from selpres.native.minibatch import ACTIVATIONS, RULES

    unknown = sorted(k for k, v in hparams.items() if v is not None and k != "lr" and k not in HPARAM_DEFAULTS)
    for what, value, known in (
        ("optim._target_", rule, RULES),
        ("model.activation", activation, ACTIVATIONS),
        ("optim.lr_schedule", lr_schedule, LR_SCHEDULES),
        ("optim.reduction", reduction, REDUCTIONS),
    ):
        if value not in known:
            return f"the native mini-batch kernel has no {what}={value} (it has {', '.join(known)})"
    if unknown:
        return f"the native mini-batch kernel reads no optim.{unknown[0]}"
    return None


class NativeMiniBatchEngine(ScoredByPredict):
    """R replicas, mini-batches of ``batch_size``, ``rule`` in sgd/adam/adamw, on the native kernel."""

    name = NAME
    LANES = 4
    _pack, _unpack, _lanes = NativeEngine._pack, NativeEngine._unpack, NativeEngine._lanes

    @classmethod
    def from_spec(cls, spec, params):
        """An engine of ``spec`` (:class:`selpres.engines.factory.EngineSpec`): the optimizer's keys with its
        defaults for the unset ones (as the torch engine fills them), the units, rate schedule and reduction."""
        hp = with_defaults(spec.optimizer, spec.hparams)
        args = (spec.batch_size, spec.activation, spec.lr_schedule, spec.horizon, spec.reduction)
        return cls(spec.sizes, params, spec.optimizer, hp, *args, threads=spec.threads)

    def __init__(
        self,
        sizes,
        params,
        rule: str,
        hparams: dict,
        batch_size: int,
        activation: str = "sigmoid",
        lr_schedule: str = "constant",
        horizon: float = 1.0,
        reduction: str = "mean",
        threads: int | None = None,
    ):
        from selpres.native.minibatch import RULES, load_minibatch

        self.sizes = tuple(int(s) for s in sizes)
        if len(params) != 2 * (len(self.sizes) - 1):
            raise ValueError(f"{len(params)} parameter tensors for topology {self.sizes}")
        if int(batch_size) < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        reason = native_reason(rule, activation, lr_schedule, reduction, hparams)
        if reason:
            raise KernelUnavailable(reason)
        self._k = load_minibatch(self.sizes, activation, activation == "sigmoid")
        self.rule, self.batch_size, self.activation = rule, int(batch_size), activation
        self.lr_schedule, self.horizon, self.reduction = lr_schedule, float(horizon), reduction
        self.fallback_reason = None
        self.threads = _default_threads(threads)
        h = {**HPARAM_DEFAULTS, **{k: v for k, v in hparams.items() if v is not None}}
        keys = ("lr", "momentum", "beta1", "beta2", "eps", "weight_decay")
        self._hp = torch.tensor([float(h[k]) for k in keys] + [self.horizon], dtype=torch.float64)
        # the kernel's rate: its cosine over spent / horizon (both clocks: cosine_epochs only sets spent differently)
        flags = [RULES.index(rule), int(lr_schedule != "constant"), int(reduction == "mean")]
        self._flags = torch.tensor(flags, dtype=torch.int64)
        self.lr = float(h["lr"])
        self.R = params[0].shape[0]
        self.G = -(-self.R // self.LANES)
        self.shapes = [tuple(t.shape[1:]) for t in params]
        self.P = sum(int(torch.Size(s).numel()) for s in self.shapes)
        self.w = self._pack(params)
        self.m1, self.m2 = torch.zeros_like(self.w), torch.zeros_like(self.w)
        self.steps = torch.zeros(self.G * self.LANES, dtype=torch.float64)  # each lane's optimizer steps
        self.spent = torch.zeros(self.R, dtype=torch.float64)  # each replica's cost so far (the rate's clock)
        self.epochs = 0  # epochs trained (the clock of cosine_epochs)
        self.last_losses = torch.empty(self.R, 0, dtype=torch.float64)
        self._staged = None  # a large set's rows for the kernel (selpres.native.staging), kept between epochs

    def train_epoch(self, X, Y, order, weights=None, counts=None, spent=None):
        """Mini-batches over ``order[r, :counts[r]]``; returns the [R] mean pre-update pattern loss. ``spent``: each
        replica's cost so far, the rate schedule's clock (None: the engine's own count, e.g. from a checkpoint)."""
        check_inputs(self.sizes, X, Y, order, self.R)
        if spent is not None:
            self.spent.copy_(torch.as_tensor(spent, dtype=torch.float64).expand_as(self.spent))
        epoch_clock(self.lr_schedule, self.spent, self.epochs, X.shape[0])
        self.epochs += 1
        R, m = order.shape
        weights, counts = pruned_epoch_args(order, weights, counts)
        self._staged = stage(self._staged, X, Y)
        if self._staged is not None:
            X, Y = self._staged.X, self._staged.Y
        else:
            X = X.detach().to(torch.float64).contiguous()
            Y = Y.detach().to(torch.float64).contiguous()
        o = order.detach().cpu().numpy().astype(np.int64, copy=False)
        lanes = self.G * self.LANES
        padded = torch.from_numpy(self._lanes(o) if lanes != R else np.ascontiguousarray(o))
        spent = torch.from_numpy(self._lanes(self.spent.numpy()))
        state = {"w": self.w, "m1": self.m1, "m2": self.m2, "t": self.steps, "spent": spent}
        loss = torch.zeros(lanes, dtype=torch.float64)
        pl = torch.full((lanes, m), float("nan"), dtype=torch.float64)
        extra = {}
        if counts is not None:
            extra["counts"] = torch.from_numpy(self._lanes(counts.numpy()))
        if weights is not None:
            extra["weights"] = torch.from_numpy(self._lanes(weights.numpy()))
        args = (self.sizes, state, X, Y, padded, self.batch_size, self._hp, self._flags, loss, pl, self.threads)
        self._k.train(*args, **extra)
        self.spent.copy_(spent[:R])
        self.last_losses = pl[:R]
        presented = torch.full((R,), m, dtype=torch.int64) if counts is None else counts
        return pruned_mean(loss[:R], presented)

    def predict(self, X):
        return forward_replicas(self.params(), check_patterns(self.sizes, X), self.activation)

    def finite(self):
        return torch.isfinite(self.w).all(1).reshape(-1)[: self.R]

    def params(self):
        return self._unpack(self.w)

    def state_dict(self):
        return {
            "params": self._unpack(self.w),
            "moments": [self._unpack(self.m1), self._unpack(self.m2)],
            "steps": self.steps[: self.R].clone(),
            "spent": self.spent.clone(),
            "epochs": self.epochs,
        }

    def load_state_dict(self, state):
        """Its own ``state_dict`` only: a checkpoint of the torch mini-batch engine (another layout of the optimizer's
        state) is refused, and selpres.run.checkpoint moves such a file aside and starts the job afresh."""
        if "moments" not in state:
            raise ValueError("a checkpoint of another mini-batch engine (no packed moments): not this kernel's")
        moments, steps = [self._pack(t) for t in state["moments"]], state["steps"]
        self.w = self._pack(state["params"])
        self.m1, self.m2 = moments
        self.steps = torch.from_numpy(self._lanes(steps.to(torch.float64).numpy()))
        self.spent = state["spent"].clone()
        self.epochs = int(state.get("epochs", 0))  # (older checkpoints: their clock was the cost's)
