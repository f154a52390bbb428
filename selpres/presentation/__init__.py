"""Presentation: the method itself, which patterns are presented in which epoch (stage 3 of arm -> data ->
presentation -> engine -> loop -> results -> report).

Owns the schedules of nested training sets A1 ⊂ … ⊂ A_{p+1} = U and their cost T/t (``schedule``), the paper's
counts fitted to any n (``proportions``), the strata of the input space (``partition``), priority orders whose
prefixes are the A_i (``orders``), orders chosen stage by stage from the network's losses (``selection``), the
torch Sampler and its counter-based per-epoch shuffles (``sampler``; its library arguments: ``arguments``; a
Lightning callback: ``lightning``, the one module that imports Lightning), the data-pruning policies that choose
each epoch's patterns from the losses (``pruning/``: a registry, one module per policy; SeTa's groups by the exact
1-D k-means of ``kmeans``, in C where it builds), and the space of the schedule search (``search``). Nothing here
trains: a loss-based order is handed an engine's ``predict``.

May import: ``selpres.data``, ``selpres.arms`` and the foundation (``errors``, ``seeding``, ``storage``,
``native`` for the shuffles and the k-means in C).
"""
