"""Bench: ``selpres-bench`` and ``python -m selpres.bench.scale``, speed measured side by side in one run (the last
room: it times every stage).

May import: anything in selpres.
"""
