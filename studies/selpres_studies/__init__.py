"""The studies of selpres: one module per study, its report sections composed of the report's blocks.

A study is one experiment config (``configs/experiment/<name>.yaml``) plus one module here of the same name
exporting ``SECTION(ctx) -> Section | list[Section] | None`` (None: the sweep is not this study's) and, optionally,
``ORDER`` (the order of its methods' rows, which the report's runs table follows too when the sweep is this
study's). This package is a report plug-in (:mod:`selpres.report.plugins`): every experiment config names it for its
sweep's report (``hydra.callbacks.report``), and its distribution registers it for sweeps that name none; the report
lists its public modules without importing them and leads with the study the sweep ran. So a new study is a new
module here, no list edited. Modules starting with ``_`` are the studies' helpers: ``_paper`` (the paper's Table 1,
its roles and numbers, from ``table1.yaml``), ``_families`` (families of settings in the paper's words),
``_error_cost``, ``_sensitivity``, ``_table1_plots``, ``_modern_cells``, ``_modern_claims``.

A study names no method or arm in code: what it compares comes from the jobs' results.json, its roles (which method
is the reference, which the baseline or partner), the rows' order, display names and a paper's numbers from its
design, ``<name>.yaml`` beside its module (``table1.yaml``, ``modern.yaml``). Table 1 (``table1``) is a study like
the others: its grid against the paper, verdicts, time to target and figures; its sections also close the report of
a study of parameters (sensitivity, selection), compactly. ``experiment=large`` needs no module: one n's folder is
Table 1's grid on its arms, the whole sweep the selection study's.

Apart from the library (the repository's ``studies/`` distribution, not in selpres's wheel), it uses selpres's public
API only, as a user's own study would: :mod:`selpres` (``load_task``) and the report's blocks, :mod:`selpres.report`
(``tests/test_layout.py`` checks it). Nothing in selpres imports it.
"""
