"""The online engines: SGD with momentum on mini-batches of ``batch_size`` (the paper's ``batch_size`` 1), sigmoid
units, a constant rate, for R independent replicas (the ``online`` mode of :mod:`selpres.engines.factory`).

Every engine here does the same thing, defined by :class:`ReferenceEngine` (plain PyTorch, one ``nn.Module`` and one
``torch.optim.SGD`` per replica); the others only do it faster:

* ``reference`` -- :class:`ReferenceEngine`: the idiomatic loop. Read it to know what the others do.
* ``torch``     -- :class:`TorchEngine`: all replicas at once in eager PyTorch (batched matmuls, hand-written
  sigmoid/MSE backward). Pure torch; what ``engine=fast`` runs where no native kernel can be built.
* ``native``    -- :class:`NativeEngine`: an AVX2 C kernel (4 float64 replicas per vector, inline vector ``exp``,
  topology compiled in; ``selpres/native/kernels/sgd.c``), built with the system C compiler at first use and cached
  (see :mod:`selpres.native`); raises :class:`selpres.native.KernelUnavailable` where it cannot run. Its
  ``predict`` runs the kernel's forward pass on the packed weights; its ``squared_errors`` sums inside that pass,
  writing no outputs; its ``finite`` reads the packed weights once, without unpacking them.

Which one a job gets, and the fallback of ``fast``, is :func:`selpres.engines.factory.build_engine`'s; what every
engine offers is :class:`selpres.engines.factory.Engine`. Each class here is built by ``from_spec(spec, params)``
(params [W1, b1, ...], leading dim R), or directly with ``(sizes, params, lr, momentum, batch_size)``.

Semantics: replica r presents ``X[order[r, j]]`` for j = 0..m-1 in consecutive mini-batches of ``batch_size`` (the
last may be smaller); per mini-batch the loss is ``mse_loss(out, target)`` (mean over batch and outputs), then
``zero_grad(); backward(); step()`` with ``SGD(lr, momentum)`` (no dampening/nesterov/weight decay):
``buf = momentum*buf + g; p -= lr*buf``. Momentum buffers persist across ``train_epoch`` calls and are part of
``state_dict``.

Pruned epochs (the data-pruning schedules, :mod:`selpres.presentation.pruning`): with ``counts`` [R] replica r
presents only ``order[r, :counts[r]]``, in its own mini-batches (the last may be smaller; a replica with nothing
left does not step: its weights and momenta stay as they are), and with ``weights`` [R, m] pattern j's loss is
weighted: a mini-batch's loss is the mean over its patterns of ``weight * mse`` (InfoBatch's rescaled loss; at
batch 1 the pattern's gradient times its weight). ``last_losses`` [R, m] then holds each presented pattern's mse
before its update (NaN past counts[r]): InfoBatch's scores, at no extra cost. The mini-batch engine
(:mod:`selpres.engines.minibatch`) defines the same for its other optimizers; with ``optim.reduction=mean`` and sgd
it is this update. An epoch without ``counts`` or ``weights`` leaves ``last_losses`` empty ([R, 0]).

Threads: ``native`` splits replicas (in groups of 4; in ``predict`` and ``squared_errors``, patterns when there are
fewer groups than threads) over up to ``threads`` OS threads, and runs small calls (a few replicas, a few patterns)
in the calling thread (see :data:`selpres.native.library.MIN_THREAD_WORK`); the default is
``torch.get_num_threads()`` (set it, or the spec's ``threads=1``, e.g. when a joblib sweep already runs one process
per core). Environment variable ``SELPRES_THREADS`` overrides the default.
"""

from __future__ import annotations

import os

import numpy as np
import torch
import torch.nn.functional as F

from selpres.engines.inputs import check_inputs, check_patterns, check_scoring, pruned_epoch_args, pruned_mean
from selpres.engines.model import BPN, forward_replicas, load_into, replicas_finite, squared_errors_of
from selpres.engines.optim import check_hparams
from selpres.native.staging import stage


def _default_threads(threads: int | None) -> int:
    if threads is None:
        env = os.environ.get("SELPRES_THREADS")
        threads = int(env) if env else torch.get_num_threads()
    return max(1, int(threads))


class OnlineSGD:
    """What the online engines share: built from a spec as SGD with momentum at the spec's rate."""

    @staticmethod
    def rate(spec) -> tuple[float, float]:
        """(lr, momentum) of ``spec``'s optimizer, checked, SGD's defaults for the unset ones."""
        hp = check_hparams(spec.optimizer, spec.hparams)
        return hp["lr"], hp["momentum"]

    @classmethod
    def from_spec(cls, spec, params):
        """An engine of ``spec`` (:class:`selpres.engines.factory.EngineSpec`) from weights ``params``."""
        return cls(spec.sizes, params, *cls.rate(spec), spec.batch_size)


# ----------------------------------------------------------------------------------------------
# reference: the idiomatic code that defines correct results
# ----------------------------------------------------------------------------------------------
class ScoredByPredict:
    """``squared_errors`` from ``predict``'s [R, N, out] outputs: for the engines without a fused scoring
    pass (reference, torch, batch); needs ``self.sizes`` and ``self.predict``."""

    @property
    def evaluation(self) -> str:
        return f"{self.name} (outputs from predict)"

    def squared_errors(self, X, Y):
        X, Y = check_scoring(self.sizes, X, Y)
        return squared_errors_of(self.predict(X), Y)


class ReferenceEngine(OnlineSGD, ScoredByPredict):
    """One ``BPN`` + one ``torch.optim.SGD`` per replica, trained pattern by pattern with autograd."""

    name = "reference"
    fallback_reason: str | None = None

    def __init__(self, sizes, params, lr, momentum, batch_size):
        self.sizes = tuple(sizes)
        self.batch_size = int(batch_size)
        self.R = params[0].shape[0]
        self.models = [load_into(BPN(self.sizes), params, r) for r in range(self.R)]
        self.optimizers = [torch.optim.SGD(m.parameters(), lr=lr, momentum=momentum) for m in self.models]
        self.last_losses = torch.empty(self.R, 0, dtype=torch.float64)

    def train_epoch(self, X, Y, order, weights=None, counts=None, spent=None):  # spent: a constant rate's, unused
        check_inputs(self.sizes, X, Y, order, self.R)
        m = order.shape[1]
        weights, counts = pruned_epoch_args(order, weights, counts)
        if counts is not None:
            self.last_losses = torch.full((self.R, m), float("nan"), dtype=torch.float64)
        losses = torch.zeros(self.R, dtype=torch.float64)
        for r, (model, opt) in enumerate(zip(self.models, self.optimizers)):
            total, c = 0.0, m if counts is None else int(counts[r])
            for start in range(0, c, self.batch_size):
                idx = order[r, start : min(start + self.batch_size, c)]
                out = model(X[idx])
                if counts is None:
                    loss = F.mse_loss(out, Y[idx])
                else:  # each pattern's mse; the loss is their mean over the mini-batch, each weighted
                    per = F.mse_loss(out, Y[idx], reduction="none").mean(-1)
                    w = 1.0 if weights is None else weights[r, start : start + len(idx)]
                    loss = (per * w).mean()
                    per = per.detach()
                    self.last_losses[r, start : start + len(idx)] = per
                opt.zero_grad()
                loss.backward()
                opt.step()
                # the epoch's loss is unweighted: the batch mean back to a per-pattern sum
                total += loss.item() * len(idx) if counts is None else float(per.sum())
            losses[r] = total / c if c else float("nan")
        return losses

    def predict(self, X):
        return forward_replicas(self.params(), check_patterns(self.sizes, X))

    def finite(self):
        return replicas_finite(self.params())

    def params(self):
        return [
            torch.stack(group)
            for group in zip(*([p.detach().clone() for p in model.flat_params()] for model in self.models))
        ]

    def _momentum(self, model, opt):
        out = []
        for p in model.flat_params():
            buf = opt.state.get(p, {}).get("momentum_buffer")
            out.append(torch.zeros_like(p.detach()) if buf is None else buf.detach().clone())
        return out

    def state_dict(self):
        mom = [self._momentum(model, opt) for model, opt in zip(self.models, self.optimizers)]
        return {"params": self.params(), "momentum": [torch.stack(group) for group in zip(*mom)]}

    def load_state_dict(self, state):
        for r, (model, opt) in enumerate(zip(self.models, self.optimizers)):
            load_into(model, state["params"], r)
            for p, buf in zip(model.flat_params(), state["momentum"]):
                opt.state[p]["momentum_buffer"] = buf[r].detach().clone().to(p.dtype)


# ----------------------------------------------------------------------------------------------
# torch: all replicas at once, eager PyTorch (the pure-torch fallback)
# ----------------------------------------------------------------------------------------------
class TorchEngine(OnlineSGD, ScoredByPredict):
    """Replica-batched eager PyTorch with a hand-written backward. Same updates as the reference."""

    name = "torch"
    fallback_reason: str | None = None

    def __init__(self, sizes, params, lr, momentum, batch_size):
        self.sizes = tuple(sizes)
        self.lr, self.mom, self.batch_size = float(lr), float(momentum), int(batch_size)
        self.R = params[0].shape[0]
        self.p = [t.detach().to(torch.float64).clone().contiguous() for t in params]
        self.buf = [torch.zeros_like(t) for t in self.p]
        self.last_losses = torch.empty(self.R, 0, dtype=torch.float64)

    @torch.no_grad()
    def train_epoch(self, X, Y, order, weights=None, counts=None, spent=None):  # spent: a constant rate's, unused
        check_inputs(self.sizes, X, Y, order, self.R)
        R, m = order.shape
        weights, counts = pruned_epoch_args(order, weights, counts)
        X, Y = X.to(torch.float64), Y.to(torch.float64)
        Ws, bs = self.p[0::2], self.p[1::2]
        Wm, bm = self.buf[0::2], self.buf[1::2]
        nout = self.sizes[-1]
        total = torch.zeros(R, dtype=torch.float64)
        if counts is not None:
            self.last_losses = torch.full((R, m), float("nan"), dtype=torch.float64)
        for start in range(0, m if counts is None else int(counts.max()), self.batch_size):
            idx = order[:, start : start + self.batch_size]  # [R, B]
            B = idx.shape[1]
            acts = [X[idx]]  # [R, B, in]
            for W, b in zip(Ws, bs):
                acts.append(torch.sigmoid(torch.baddbmm(b.unsqueeze(1), acts[-1], W.transpose(1, 2))))
            y, t = acts[-1], Y[idx]
            diff = y - t
            active = None
            if counts is None:
                total += diff.square().sum(dim=(1, 2)) / nout
                delta = diff * (2.0 / (B * nout)) * y * (1 - y)  # dL/dz of the output layer, [R, B, out]
            else:  # each replica's own mini-batch: its first nb columns, each weighted
                nb = (counts - start).clamp(0, B)
                valid = torch.arange(B).unsqueeze(0) < nb.unsqueeze(1)  # [R, B]
                per = diff.square().mean(-1)
                self.last_losses[:, start : start + B] = torch.where(valid, per, float("nan"))
                total += torch.where(valid, per, 0.0).sum(1)
                w = (
                    valid.to(torch.float64)
                    if weights is None
                    else torch.where(valid, weights[:, start : start + B], 0.0)
                )
                scale = (2.0 / (nb.clamp(min=1).to(torch.float64) * nout)).unsqueeze(1) * w
                delta = diff * scale.unsqueeze(2) * y * (1 - y)
                active = nb > 0
            for layer in range(len(Ws) - 1, -1, -1):
                a_prev = acts[layer]
                gW = torch.bmm(delta.transpose(1, 2), a_prev)
                gb = delta.sum(dim=1)
                if layer:
                    delta = torch.bmm(delta, Ws[layer]) * a_prev * (1 - a_prev)  # uses W before its update
                for p, buf, g in ((Ws[layer], Wm[layer], gW), (bs[layer], bm[layer], gb)):
                    if active is None:
                        buf.mul_(self.mom).add_(g)
                        p.sub_(buf, alpha=self.lr)
                    else:  # a replica with nothing left keeps its weights and momenta
                        keep = active.view(R, *([1] * (p.dim() - 1)))
                        new_buf = buf.mul(self.mom).add_(g)
                        p.copy_(torch.where(keep, p.sub(new_buf, alpha=self.lr), p))
                        buf.copy_(torch.where(keep, new_buf, buf))
        if counts is not None:
            return pruned_mean(total, counts)
        return total / m if m else torch.full((R,), float("nan"), dtype=torch.float64)

    def predict(self, X):
        return forward_replicas(self.p, check_patterns(self.sizes, X))

    def finite(self):
        return replicas_finite(self.p)

    def params(self):
        return [t.clone() for t in self.p]

    def state_dict(self):
        return {"params": self.params(), "momentum": [t.clone() for t in self.buf]}

    def load_state_dict(self, state):
        self.p = [t.detach().to(torch.float64).clone().contiguous() for t in state["params"]]
        self.buf = [t.detach().to(torch.float64).clone().contiguous() for t in state["momentum"]]


# ----------------------------------------------------------------------------------------------
# native: the C kernel
# ----------------------------------------------------------------------------------------------
class NativeEngine(OnlineSGD):
    """AVX2 C kernel over groups of 4 replicas (replica index innermost), threads over groups."""

    name = "native"
    fallback_reason: str | None = None

    @property
    def evaluation(self) -> str:
        lanes = self._k.eval_lanes
        return f"native, {lanes} lanes ({'AVX-512' if lanes == 8 else 'AVX2'})"

    LANES = 4

    @classmethod
    def from_spec(cls, spec, params):
        return cls(spec.sizes, params, *cls.rate(spec), spec.batch_size, threads=spec.threads)

    def __init__(self, sizes, params, lr, momentum, batch_size, threads: int | None = None):
        from selpres.native import load

        self._k = load(sizes)  # raises KernelUnavailable when it cannot be built
        self.sizes = tuple(sizes)
        self.lr, self.mom, self.batch_size = float(lr), float(momentum), int(batch_size)
        self.threads = _default_threads(threads)
        self.R = params[0].shape[0]
        self.G = -(-self.R // self.LANES)
        self.shapes = [tuple(t.shape[1:]) for t in params]
        self.P = sum(int(torch.Size(s).numel()) for s in self.shapes)
        self.w = self._pack(params)
        self.buf = torch.zeros_like(self.w)
        self.last_losses = torch.empty(self.R, 0, dtype=torch.float64)
        self._staged = None  # a large set's rows for the kernel (selpres.native.staging), kept between epochs

    # [W1, b1, ...] with leading R  <->  [G, P, 4] (per group: parameters in list order, 4 lanes innermost)
    def _pack(self, tensors):
        flat = torch.cat([t.detach().to(torch.float64).reshape(self.R, -1) for t in tensors], dim=1)  # [R, P]
        # padding lanes (R not a multiple of 4) shadow replica 0, here and in train_epoch's orders: lanes of
        # zeros trained on one pattern drive their errors into subnormal numbers, which made the whole group
        # ~13x slower (found by bench_scale); a copy of replica 0 stays as normal as replica 0 itself
        padded = flat[:1].repeat(self.G * self.LANES, 1)
        padded[: self.R] = flat
        return padded.reshape(self.G, self.LANES, self.P).transpose(1, 2).contiguous()

    def _unpack(self, packed):
        """Per-layer copies in numpy: a torch copy here wakes torch's OpenMP pool, ~1 ms a call between
        epochs of the kernel (see train_epoch); checkpoints unpack both weights and momenta."""
        a, out, k = packed.numpy(), [], 0
        for s in self.shapes:
            n = int(torch.Size(s).numel())
            layer = np.ascontiguousarray(a[:, k : k + n, :].transpose(0, 2, 1)).reshape(self.G * self.LANES, n)
            out.append(torch.from_numpy(layer[: self.R].reshape(self.R, *s)))
            k += n
        return out

    def train_epoch(self, X, Y, order, weights=None, counts=None, spent=None):  # spent: a constant rate's, unused
        check_inputs(self.sizes, X, Y, order, self.R)
        m = order.shape[1]
        weights, counts = pruned_epoch_args(order, weights, counts)
        # a large set is staged once, whatever its dtype and layout (selpres.native.staging); None for one
        # that stays in the caches, read as it is
        self._staged = stage(self._staged, X, Y)
        if self._staged is not None:
            X, Y = self._staged.X, self._staged.Y  # the same numbers, one row of whole cache lines per pattern
        else:
            X = X.detach().to(torch.float64).contiguous()
            Y = Y.detach().to(torch.float64).contiguous()
        # numpy, not torch, for the padding: a large torch op would wake torch's OpenMP pool, whose
        # spinning threads then compete with the kernel's threads for the cores
        if self.R == self.G * self.LANES and order.dtype == torch.int64 and order.is_contiguous():
            padded_order = order  # no padding lanes: the kernel reads the orders as they are
        else:  # the padding lanes shadow replica 0 (see _pack)
            padded_order = torch.from_numpy(self._lanes(order.detach().cpu().numpy().astype(np.int64, copy=False)))
        loss = torch.zeros(self.G * self.LANES, dtype=torch.float64)
        pruned = {}
        if counts is not None:  # per lane, the padding lanes shadowing replica 0 (numpy: see above)
            pruned["counts"] = torch.from_numpy(self._lanes(counts.numpy()))
            if weights is not None:
                pruned["weights"] = torch.from_numpy(self._lanes(weights.numpy()))
            pl = np.full((self.G * self.LANES, m), np.nan)
            pruned["pattern_losses"] = torch.from_numpy(pl)
        args = (self.sizes, self.w, self.buf, X, Y, padded_order, self.batch_size, self.lr, self.mom, loss)
        self._k.train(*args, self.threads, **pruned)
        if counts is not None:
            self.last_losses = torch.from_numpy(pl[: self.R])
            return pruned_mean(loss[: self.R], counts)
        return (loss[: self.R] / m) if m else torch.full((self.R,), float("nan"), dtype=torch.float64)

    def _lanes(self, a: np.ndarray) -> np.ndarray:
        """A per-replica array [R, ...] for every lane [G*4, ...], the padding lanes copying replica 0."""
        out = np.empty((self.G * self.LANES, *a.shape[1:]), dtype=a.dtype)
        out[: self.R] = a
        out[self.R :] = a[:1]
        return out

    def predict(self, X):
        """The kernel's forward pass on the packed weights (4 replicas per vector, threads over groups)."""
        out = self._k.forward(self.sizes, self.w, check_patterns(self.sizes, X), self.threads)
        return out[: self.R]

    def squared_errors(self, X, Y):
        """Summed inside the kernel's forward pass: no [R, N, out] outputs are written (the RMS follows in
        the train loop: sqrt(sum / N), in Nm times (y_max - y_min) / (hi - lo) of the output's scaler)."""
        X, Y = check_scoring(self.sizes, X, Y)
        return self._k.squared_errors(self.sizes, self.w, X, Y, self.threads)[: self.R]

    def finite(self):
        """On the packed [G, P, 4] weights, in one pass (no unpacking)."""
        return self._k.finite(self.w)[: self.R]

    def params(self):
        return self._unpack(self.w)

    def state_dict(self):
        return {"params": self._unpack(self.w), "momentum": self._unpack(self.buf)}

    def load_state_dict(self, state):
        self.w = self._pack(state["params"])
        self.buf = self._pack(state["momentum"])
