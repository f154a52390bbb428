"""The studies: one module per study, that study's report sections, composed of the report's shared blocks.

A study is one experiment config (``selpres/configs/experiment/<name>.yaml``) plus one module here of the same
name exporting ``SECTION(ctx) -> Section | list[Section] | None`` (None: the sweep is not this study's) and,
optionally, ``ORDER`` (the order of its methods' rows, which the report's runs table follows too when the sweep is
this study's). The report finds the modules through :data:`selpres.report.build.STUDIES` (a registry: a new study is
a new module, no list edited) and leads with the sections of the study the sweep ran. Modules starting with ``_``
are the studies' helpers: ``_paper`` (the paper's Table 1, its roles and numbers, from ``table1.yaml``),
``_families`` (families of settings in the paper's words), ``_error_cost``, ``_sensitivity``, ``_table1_plots``.

A study names no method or arm in code: what it compares comes from the jobs' results.json, its roles (which method
is the reference, which the baseline or partner), the rows' order, display names and a paper's numbers from its
design, ``<name>.yaml`` beside its module (``table1.yaml``, ``modern.yaml``). Table 1 (``table1``) is a study like
the others: its grid against the paper, verdicts, time to target and figures; its sections also close the report of
a study of parameters (sensitivity, selection), compactly. ``experiment=large`` needs no module: one n's folder is
Table 1's grid on its arms, the whole sweep the selection study's.

The last room of the report's side: it may import ``selpres.report`` (the building blocks), ``selpres.run``
(stats), ``selpres.data`` (a task's held-out targets) and the foundation. Nothing in the library imports it:
``import selpres`` and the core (arms -> engines, the Sampler, run, report's blocks) work without it.
"""
