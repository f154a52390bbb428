"""Native: the C code, compiled on first use and cached (part of the foundation every stage may import).

Owns the build, cache and ctypes binding of ``kernels/sgd.c`` (online SGD and scoring for the ``native`` engine),
``kernels/minibatch.c`` (mini-batch SGD/Adam/AdamW for ``selpres.engines.native_minibatch``; ``minibatch.py``,
``load_minibatch`` there) and ``kernels/shuffle.c`` (the per-epoch shuffles of ``selpres.presentation.sampler``).
It stands below its users, so none has to import another; without a compiler or AVX2/FMA, ``KernelUnavailable`` says why
and the callers fall back to torch.

What callers use, all from here: ``from selpres.native import KernelUnavailable, cpu_flags, load, load_shuffle``.
The modules: ``build.py`` (compile, cache, load once per process), ``library.py`` (a loaded library and the
thread pool its calls' chunks run on), ``sgd.py`` (the SGD kernel's binding, ``load``), ``shuffle.py`` (the
shuffles' binding, ``load_shuffle``), ``staging.py`` (a large set's rows laid out for the SGD kernel). ``load``
and ``load_shuffle`` are imported on first use, so importing ``KernelUnavailable`` does not import torch.

May import: ``selpres.errors`` only (and numpy, torch, ctypes).
"""

from selpres.native.build import KernelUnavailable, cpu_flags

__all__ = ["KernelUnavailable", "cpu_flags", "load", "load_shuffle"]


def __getattr__(name: str):
    if name == "load":
        from selpres.native.sgd import load

        return load
    if name == "load_shuffle":
        from selpres.native.shuffle import load_shuffle

        return load_shuffle
    raise AttributeError(f"module 'selpres.native' has no attribute {name!r}")
