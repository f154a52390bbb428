"""Native: the C code, compiled on first use and cached (part of the foundation every stage may import).

Owns the build, cache and ctypes binding of ``kernels/sgd.c`` (online SGD and scoring for the ``native`` engine),
``kernels/minibatch.c`` (mini-batch SGD/Adam/AdamW for ``selpres.engines.native_minibatch``; ``minibatch.py``,
``load_minibatch`` there), ``kernels/shuffle.c`` (the per-epoch shuffles of ``selpres.presentation.sampler``) and
``kernels/kmeans1d.c`` (exact 1-D k-means for ``selpres.presentation.kmeans``). It stands below its users, so none
has to import another; without a compiler or AVX2/FMA, ``KernelUnavailable`` says why and the callers fall back
to torch (or numpy).

What callers use, all from here: ``from selpres.native import KernelUnavailable, cpu_flags, load, load_shuffle,
load_kmeans``.
The modules: ``build.py`` (compile, cache, load once per process), ``library.py`` (a loaded library and the
thread pool its calls' chunks run on), ``sgd.py`` (the SGD kernel's binding, ``load``), ``shuffle.py`` (the
shuffles' binding, ``load_shuffle``), ``kmeans.py`` (the k-means' binding, ``load_kmeans``), ``staging.py`` (a
large set's rows laid out for the SGD kernel). ``load``, ``load_shuffle`` and ``load_kmeans`` are imported on
first use, so importing ``KernelUnavailable`` does not import torch.

May import: ``selpres.errors`` only (and numpy, torch, ctypes).
"""

from selpres.native.build import KernelUnavailable, cpu_flags

__all__ = ["KernelUnavailable", "cpu_flags", "load", "load_kmeans", "load_shuffle"]


def __getattr__(name: str):
    if name == "load":
        from selpres.native.sgd import load

        return load
    if name == "load_shuffle":
        from selpres.native.shuffle import load_shuffle

        return load_shuffle
    if name == "load_kmeans":
        from selpres.native.kmeans import load_kmeans

        return load_kmeans
    raise AttributeError(f"module 'selpres.native' has no attribute {name!r}")
