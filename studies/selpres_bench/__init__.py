"""Bench: ``selpres-bench``, ``python -m selpres.bench.scale`` and ``python -m selpres.bench.pruning``, speed
measured side by side in one run (the last room: it times every stage).

May import: anything in selpres.
"""
