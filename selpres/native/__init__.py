"""Native: the C code, compiled on first use and cached (part of the foundation every stage may import).

Owns the build, cache and ctypes binding of ``kernels/sgd.c`` (online SGD and scoring for the ``native`` engine)
and ``kernels/shuffle.c`` (the per-epoch shuffles of ``selpres.presentation.sampler``). It stands below both of
its users, so neither has to import the other; without a compiler or AVX2/FMA, ``KernelUnavailable`` says why
and the callers fall back to torch.

May import: ``selpres.errors`` only (and numpy, torch, ctypes).
"""
