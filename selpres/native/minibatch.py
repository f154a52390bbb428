"""The native mini-batch kernel (``kernels/minibatch.c``): its ctypes binding, built by ``build.py``.

One library per topology and units (``-DACT``, ``-DOUT_SIGMOID``, with the topology macros of ``sgd.py``): the
hidden units' function is compiled in, the optimizer and rate are arguments. The layout is the SGD kernel's
(groups of 4 replicas, ``[G, P, 4]``), so the engine packs weights as :class:`selpres.engines.online.NativeEngine`
does; the optimizer's two moments are packed the same way, each lane's step count and presentations so far are
``[G*4]`` arrays. Threads take contiguous chunks of groups (``library.py``); a lane's numbers never depend on
them.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import torch

from selpres.native.build import KERNELS, KernelUnavailable, compile_library, load_once
from selpres.native.library import Library
from selpres.native.sgd import LANES, TRAIN_WORK_PER_PARAMETER, macros

SOURCE = KERNELS / "minibatch.c"
ACTIVATIONS = ("sigmoid", "tanh", "relu", "silu", "leaky_relu")  # -DACT=0..4, in this order (the C file's hidden4)
RULES = ("sgd", "adam", "adamw")  # its RULE_* constants
NP = 8  # patterns of a mini-batch advanced together (the C file's present; 8 measured ~10 % ahead of 4 at 18-40-6)


class MiniBatchKernel(Library):
    """One topology's and units' compiled library: :meth:`train` runs an epoch of mini-batches."""

    def __init__(self, path: Path):
        super().__init__(path)
        i64, p = ctypes.c_int64, ctypes.c_void_p
        self._train = self.lib.selpres_mb_train
        self._train.argtypes = [ctypes.c_int, p, i64, i64, i64, *[p] * 8, i64, i64, p, p, p, p, i64, i64, p, p]
        self._train.restype = ctypes.c_int
        self._sizes: dict[tuple[int, ...], torch.Tensor] = {}

    def train(
        self,
        sizes,
        state: dict,
        X: torch.Tensor,
        Y: torch.Tensor,
        order: torch.Tensor,
        batch_size: int,
        hp: torch.Tensor,
        flags: torch.Tensor,
        loss: torch.Tensor,
        plosses: torch.Tensor,
        threads: int,
        counts: torch.Tensor | None = None,
        weights: torch.Tensor | None = None,
    ) -> None:
        """One epoch for every group of ``state`` (``w``, ``m1``, ``m2`` [G, P, 4]; ``t``, ``spent`` [G*4];
        all float64 and updated in place). ``hp`` [7] float64: lr, momentum, beta1, beta2, eps, weight_decay,
        horizon; ``flags`` [3] int64: rule (index in :data:`RULES`), cosine, mean reduction. ``loss`` [G*4]
        gets each lane's summed pattern loss, ``plosses`` [G*4, m] each presented pattern's. ``counts`` [G*4]
        int64 and ``weights`` [G*4, m] float64: a pruned epoch (None: all of ``order``, weight 1)."""
        w = state["w"]
        G, P, lanes = w.shape
        m = order.shape[1]
        assert lanes == LANES and order.dtype == torch.int64 and order.is_contiguous() and order.shape[0] == G * LANES
        for key in ("w", "m1", "m2"):
            assert state[key].shape == w.shape and state[key].is_contiguous() and state[key].dtype == torch.float64
        for t, dtype, shape in [
            (state["t"], torch.float64, (G * LANES,)),
            (state["spent"], torch.float64, (G * LANES,)),
            (loss, torch.float64, (G * LANES,)),
            (plosses, torch.float64, (G * LANES, m)),
            (hp, torch.float64, (7,)),
            (flags, torch.int64, (3,)),
            (counts, torch.int64, (G * LANES,)),
            (weights, torch.float64, (G * LANES, m)),
        ]:
            assert t is None or (t.dtype == dtype and tuple(t.shape) == shape and t.is_contiguous())
        assert X.dtype == Y.dtype == torch.float64 and X.stride(1) == 1 and Y.stride(1) == 1
        key = tuple(sizes)
        if key not in self._sizes:
            self._sizes[key] = torch.tensor(key, dtype=torch.int64)
        threads = self.threads_for(TRAIN_WORK_PER_PARAMETER * G * LANES * m * P, threads)
        ptrs = [state[k].data_ptr() for k in ("w", "m1", "m2", "t", "spent")]
        rest = (
            P,
            *ptrs,
            X.data_ptr(),
            Y.data_ptr(),
            order.data_ptr(),
            m,
            int(batch_size),
            hp.data_ptr(),
            flags.data_ptr(),
            loss.data_ptr(),
            plosses.data_ptr(),
            X.stride(0) if X.shape[0] > 1 else X.shape[1],
            Y.stride(0) if Y.shape[0] > 1 else Y.shape[1],
            None if counts is None else counts.data_ptr(),
            None if weights is None else weights.data_ptr(),
        )
        head = (len(key) - 1, self._sizes[key].data_ptr())
        self._run(self._train, [(*head, g0, g1, *rest) for g0, g1 in self._bounds(G, threads)])


def mb_macros(sizes, activation: str, out_sigmoid: bool) -> list[str]:
    """The ``-D`` flags that specialise ``kernels/minibatch.c``: the topology (as for the SGD kernel) and units."""
    topo = [f for f in macros(sizes) if not f.startswith("-DNI=")]
    return [*topo, f"-DACT={ACTIVATIONS.index(activation)}", f"-DOUT_SIGMOID={int(out_sigmoid)}", f"-DNP={NP}"]


def load_minibatch(sizes, activation: str, out_sigmoid: bool) -> MiniBatchKernel:
    """The mini-batch kernel for ``sizes`` and these units (see :func:`selpres.native.build.load_once`)."""
    sizes = tuple(int(s) for s in sizes)
    if activation not in ACTIVATIONS:
        raise KernelUnavailable(f"no native kernel for {activation} units (it has {', '.join(ACTIVATIONS)})")
    if len(sizes) - 1 > 32:
        raise KernelUnavailable("more than 32 layers")
    flags = mb_macros(sizes, activation, out_sigmoid)
    stem = f"selpres_mb_{'-'.join(map(str, sizes))}_{activation}{'_sig' if out_sigmoid else ''}"
    return load_once(
        ("minibatch", sizes, activation, bool(out_sigmoid)),
        MiniBatchKernel,
        lambda: compile_library(stem, SOURCE, flags),
    )
