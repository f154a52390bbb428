"""The studies: one module per study, that study's report section, composed of the report's shared blocks.

A study is one experiment config (``selpres/configs/experiment/<name>.yaml``) plus one module here of the same
name exporting ``SECTION(ctx) -> Section | list[Section] | None`` (None: the sweep is not this study's). The
report finds the modules through :data:`selpres.report.build.STUDIES` (a registry: a new study is a new module,
no list edited) and leads with the sections of the study the sweep ran. Modules starting with ``_`` are a
study's helpers. A study names no method or arm in code: what it compares comes from the jobs' results.json and
its study design (``selpres/configs/study/<name>.yaml``). Table 1 and ``experiment=large`` need no module: the
report's generic sections (Table 1's grid, verdicts, time to target, plots, runs) are their report.

The last room of the report's side: it may import ``selpres.report`` (the building blocks), ``selpres.run``
(stats), ``selpres.data`` (a task's held-out targets) and the foundation. Nothing in the library imports it:
``import selpres`` and the core (arms -> engines, the Sampler, run, report's blocks) work without it.
"""
