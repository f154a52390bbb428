"""Batch-mode training of R replicas at once: one gradient per replica and one optimizer step per epoch.

QuickProp, Delta-Bar-Delta, Rprop (and Adam or SGD used this way) are batch methods: each epoch
presents its m patterns, sums their error gradients and then updates once. :class:`BatchEngine` does
that for all R replicas together: the epoch's presentations of every replica go through one
replica-batched forward pass (``order[r]`` says which patterns replica r sees; repeats count twice),
autograd gives each replica the gradient of its own error, and one step of a ``torch.optim``
optimizer (:mod:`selpres.engines.optim`) updates the stacked ``[R, ...]`` parameters. Every rule offered is
elementwise, so stepping the stack is stepping R separate optimizers (tested against R separate
``BPN`` + optimizer runs). Cost stays in presentations: an epoch of m patterns is m forward and
backward passes per replica, the same axis as online training.

The epoch's error per replica (``reduction``):

* ``"sum"`` (default): ``E = 1/2 sum_p sum_k e_pk^2`` over the epoch's presentations, Rumelhart's
  error summed over the epoch as Fahlman and Jacobs used it, so that their step sizes (and rules of
  thumb such as Tveter's QuickProp epsilon ~ 1/n) keep their published meaning. Under selective
  presentation a smaller training set A_i then gives a proportionally smaller gradient.
* ``"mean"``: ``mse_loss`` over the presentations and the outputs, the loss of every engine in
  :mod:`selpres.engines.online`: batch SGD here equals ``TorchEngine`` with ``batch_size = m`` (tested), and a
  step size means the same in stages of every size. ``grad_mean = grad_sum * 2 / (m * n_out)``.

The ``batch`` mode of :mod:`selpres.engines.factory` (its one implementation: torch); online SGD is
:mod:`selpres.engines.online`.
"""

from __future__ import annotations

import copy

import torch

from selpres.engines.inputs import check_inputs
from selpres.engines.model import forward_replicas, replicas_finite
from selpres.engines.online import ScoredByPredict
from selpres.engines.optim import make_optimizer, offset_sigmoid
from selpres.engines.optim._base import require
from selpres.errors import ConfigError

REDUCTIONS = ("mean", "sum")
CHUNK = 1 << 16  # replica-presentations per forward/backward chunk (bounds memory; results agree to rounding)


def check_batch_options(sigmoid_prime_offset, reduction) -> tuple[float, str]:
    """The batch-mode options, checked (ConfigError naming ``optim.<key>``): (offset, reduction)."""
    if reduction not in REDUCTIONS:
        raise ConfigError("optim.reduction", reduction, f"one of {', '.join(REDUCTIONS)}")
    offset = require(
        "optim.sigmoid_prime_offset",
        sigmoid_prime_offset,
        "an offset >= 0 added to sigma' (Fahlman: 0.1; 0 = exact gradient)",
        lambda v: v >= 0,
    )
    return offset, reduction


class BatchEngine(ScoredByPredict):
    """R replicas of the sigmoid BPN trained in batch mode with one optimizer over the stacked weights.

    ``optimizer`` and ``hparams``: see :func:`selpres.engines.optim.make_optimizer`. ``sigmoid_prime_offset``:
    Fahlman's offset added to sigma' in the backward pass of every layer (0 = the exact gradient).
    """

    name = "batch"
    fallback_reason = None

    @classmethod
    def from_spec(cls, spec, params):
        """An engine of ``spec`` (:class:`selpres.engines.factory.EngineSpec`): its optimizer and keys as given,
        the sigmoid-prime offset and the reduction."""
        offset, reduction = spec.sigmoid_prime_offset, spec.reduction
        return cls(spec.sizes, params, spec.optimizer, spec.hparams, sigmoid_prime_offset=offset, reduction=reduction)

    def __init__(
        self,
        sizes,
        params,
        optimizer: str = "quickprop",
        hparams: dict | None = None,
        *,
        sigmoid_prime_offset: float = 0.0,
        reduction: str = "sum",
    ):
        self.offset, self.reduction = check_batch_options(sigmoid_prime_offset, reduction)
        self.sizes = tuple(int(s) for s in sizes)
        if len(params) != 2 * (len(self.sizes) - 1):
            raise ValueError(
                f"{len(params)} parameter tensors for topology {self.sizes}: expected {2 * (len(self.sizes) - 1)}"
            )
        self.optimizer_name = optimizer
        self.R = params[0].shape[0]
        self.p = [t.detach().to(torch.float64).clone().contiguous().requires_grad_(True) for t in params]
        self.opt = make_optimizer(optimizer, self.p, hparams)
        self.last_losses = torch.empty(self.R, 0, dtype=torch.float64)  # never a pruned epoch: always empty

    def train_epoch(self, X, Y, order, weights=None, counts=None, spent=None):
        """One step per replica on the gradient of its error over ``order[r]``; returns the [R] mean
        per-pattern loss (``mse_loss`` per pattern) before the step. A batch method presents all of A_i at a
        constant rate: no counts or weights (the checks refuse a pruning schedule in batch mode)."""
        if weights is not None or counts is not None:
            raise ValueError("batch mode presents all of order[r]: no weights or counts")
        check_inputs(self.sizes, X, Y, order, self.R)
        R, m = order.shape
        if m == 0:
            return torch.full((R,), float("nan"), dtype=torch.float64)
        X, Y = X.detach().to(torch.float64), Y.detach().to(torch.float64)
        self.opt.zero_grad(set_to_none=False)
        sq = torch.empty(R, dtype=torch.float64)
        scale = 1.0 / (m * self.sizes[-1]) if self.reduction == "mean" else 0.5
        per_chunk = max(1, CHUNK // m)
        with torch.enable_grad():  # replicas are independent: the sum's gradient is each one's own
            for r0 in range(0, R, per_chunk):
                rows = slice(r0, min(R, r0 + per_chunk))
                chunk_sq = self._squared_error(X, Y, order[rows], rows)
                (chunk_sq.sum() * scale).backward()
                sq[rows] = chunk_sq.detach()
        self.opt.step()
        return sq / (m * self.sizes[-1])

    def _squared_error(self, X, Y, order, rows):
        """Sum over the presentations and outputs of the squared error, per replica of ``rows``: [r]."""
        a = X[order]  # [r, m, in]
        for W, b in zip(self.p[0::2], self.p[1::2]):
            a = offset_sigmoid(torch.baddbmm(b[rows].unsqueeze(1), a, W[rows].transpose(1, 2)), self.offset)
        return (a - Y[order]).square().sum(dim=(1, 2))

    @torch.no_grad()
    def predict(self, X):
        """Outputs of every replica: [N, in] -> [R, N, out]."""
        return forward_replicas(self.params(), X.to(torch.float64))

    def finite(self):
        """[R] bool: every weight of replica r finite (the divergence check, without copying)."""
        return replicas_finite([t.detach() for t in self.p])

    def params(self):
        return [t.detach().clone() for t in self.p]

    def state_dict(self):
        return {
            "params": self.params(),
            "optimizer_name": self.optimizer_name,
            "optimizer": copy.deepcopy(self.opt.state_dict()),
        }

    def load_state_dict(self, state):
        if state.get("optimizer_name") != self.optimizer_name:
            raise ValueError(
                f"checkpoint holds optimizer {state.get('optimizer_name')!r} state, "
                f"this engine runs {self.optimizer_name!r}"
            )
        with torch.no_grad():
            for p, src in zip(self.p, state["params"]):
                p.copy_(src)
        self.opt.load_state_dict(copy.deepcopy(state["optimizer"]))
