"""Data: exemplar sets and test sets for an arm (stage 2 of arm -> data -> presentation -> engine -> loop ->
results -> report).

Owns the paper's exemplar grid and acceleration filter (``paper``), exemplar sets drawn for any arm (``sampled``),
the user's CSV / .npz files (``file``), and the learning task of a robot/data config: exemplar set, the 10-pattern
and held-out test sets and the scaler, cached per spec (``task``), made by one route per ``data.kind``
(``routes``, a registry: ``grid``, ``sampled``, ``file``, each declaring its keys and their types, or a user's
route class by its import path; the config groups ``data/paper``, ``data/sampled`` and ``data/file`` pick them).
It reads no config: a data node arrives as a ``DataSpec`` (``spec``) and a robot node as a
``selpres.registry.Choice``, both made by ``selpres.run.specs``.

May import: ``selpres.arms`` and the foundation (``errors``, ``registry``, ``seeding``, ``storage``).
"""
