"""Presentation: the method itself, which patterns are presented in which epoch (stage 3 of arm -> data ->
presentation -> engine -> loop -> results -> report).

Owns the schedules of nested training sets A1 ⊂ … ⊂ A_{p+1} = U and their cost T/t (``schedule``), the paper's
counts fitted to any n (``proportions``), the strata of the input space (``partition``), priority orders whose
prefixes are the A_i (``orders``, fixed or chosen stage by stage), the torch Sampler and its counter-based per-epoch
shuffles (``sampler``; its library arguments: ``arguments``; a Lightning callback: ``lightning``, the one module that
imports Lightning), and the one protocol of everything that decides what an epoch presents (``selector``: a
``Selector`` asked each epoch for each replica's patterns and weights, and the job's ``Ledger`` it charges): the
paper's stages through the samplers (``staged``), the data-pruning policies that choose each epoch's patterns from
the losses (``pruning/``: a registry, one module per policy; SeTa's groups by the exact 1-D k-means of ``kmeans``,
in C where it builds), a user's own class; ``build`` makes a job's selector from a plain spec, ``selection`` holds
the network's scores they may ask for; and the space of the schedule search (``search``). Nothing here trains: a
selector is handed an engine's ``predict``.

May import: ``selpres.data``, ``selpres.arms`` and the foundation (``errors``, ``seeding``, ``storage``,
``native`` for the shuffles and the k-means in C).
"""
