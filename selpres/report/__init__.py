"""A sweep's report from its ``results.json`` files: the blocks a study's sections are made of (this package's API,
:data:`__all__`), and the report that puts together the sections of the studies it is given.

    python -m selpres.report outputs/sweeps/table1 [--out DIR]     (default DIR = <sweep>/report)
    python -m selpres.report outputs/sweeps/table1 --readme README.md   (also the block its study writes there)
    python -m selpres.report outputs/sweeps/table1 --margin 5% --holm   (equivalence margin, Holm)
    python -m selpres.report DIR --sections mylab.mystudy          (a study's sections, by import path)

**A study** is a plug-in: a module exporting ``SECTION(ctx) -> Section | list[Section] | None`` (and optionally
``ORDER``), composed of the names below and nothing else of selpres's but :mod:`selpres`'s own API; the report is
given it by the command line, the sweep's config or the installation (:mod:`selpres.report.plugins`). The paper's
and the modern studies are such plug-ins, in the repository's ``studies/`` (the ``selpres_studies`` package).

The block API (imported on first use, so ``import selpres.report`` loads nothing heavy):

- a report and a section: ``Report`` (``Report.build(sweep)``, ``.rows(csv)``), ``write_report``, ``Context`` (the
  sweep loaded once: its jobs, groups, topologies, methods, options, the experiment it ran), ``Section`` (title,
  Markdown blocks, CSV rows, figures, a README block), ``built`` (a section made, or one line saying why not),
  ``load_jobs``, ``aggregate``, ``Group`` (one method's replicas on one topology, pooled by seed);
- what the groups are: ``method_of`` (a job's method as it ran), ``method_labels`` (the one labelling of methods
  every section and study uses), ``job_cost`` and ``replica_costs`` (a job's measured cost: its mean, per replica),
  ``presents_all`` (whether a job was conventional training), ``optim_target``, ``settings``, ``setting_text``,
  ``varying``, ``base``, ``SETS``, ``UNITS``;
- comparisons: ``Options`` and ``Margin`` (the equivalence margin, Holm), ``paired``, ``paired_columns``,
  ``outcome``, ``reading``, ``adjust_family``, ``comparisons``, ``mean_curve``, ``reach``, ``time_to_target_rows``,
  ``ALPHA``, and the statistics ``summarize``, ``median``, ``tost``, ``trimmed``, ``holm``, ``clopper_pearson``,
  ``mcnemar_exact``; ``is_stalled`` (a replica's stall: its final RMS against a share of the floor's);
- blocks of sections: ``verdict`` and ``time_to_target`` (modules: a reference against every other method; the
  time-to-target tables), the figures' ``pyplot``, ``save_png``, ``draw_cost``, ``draw_curves``, ``Side``,
  ``family_styles``, ``nm_log_axis``, ``thousands``;
- Markdown: ``table``, ``fmt``, ``ci``, ``mean_std``, ``signed_interval``, ``diff_text``, ``pvalues_text``,
  ``engine_text``.

The package reads in the data's direction, one concern per module: ``jobs`` (every job folder under the sweep),
``validate`` (what the report reads of a results.json, checked at load), ``groups`` (method labels, replicas pooled
by seed), ``compare`` (paired differences and their readings, mean curves, time to target), ``markdown``,
``context`` (what every section reads and gives back), ``sections/`` (the blocks; the one generic section, the
runs), ``plugins`` (the studies a report is given), ``build`` (the report: the studies' sections, then the runs),
``callback`` (how a sweep names its plug-ins), ``readme`` (a README's generated block), ``__main__``.

Conventions: diverged replicas are left out of every mean and interval but counted; comparisons with a reference
method are paired by seed (only seeds complete in both); intervals are Student-t 95 % intervals from
:mod:`selpres.run.stats`; a verdict reads *better/worse*, *equivalent within ±m* (TOST) or *no detectable
difference*, three different things. Nothing here names a study's arms or methods: a block takes them as arguments,
or reads them from the jobs' results.json.

The last stage of arm -> data -> presentation -> engine -> loop -> results -> report: it reads job folders, never
trains. May import: ``selpres.run`` (stats, older results.json read as today's, the names of a job folder's files)
and the foundation; never a study (it is given them); matplotlib only inside the plotting blocks, so the command
line starts without it.
"""

from __future__ import annotations

import importlib

# name -> the module that owns it (a module itself where the name is the module's)
_EXPORTS = {
    "Report": "selpres.report.build",
    "built": "selpres.report.build",
    "write_report": "selpres.report.build",
    "Context": "selpres.report.context",
    "Section": "selpres.report.context",
    "load_jobs": "selpres.report.jobs",
    "method_of": "selpres.report.jobs",
    "aggregate": "selpres.report.groups",
    "Group": "selpres.report.groups",
    "optim_target": "selpres.report.groups",
    "method_labels": "selpres.report.groups",
    "job_cost": "selpres.report.groups",
    "replica_costs": "selpres.report.groups",
    "presents_all": "selpres.report.groups",
    "settings": "selpres.report.groups",
    "setting_text": "selpres.report.groups",
    "varying": "selpres.report.groups",
    "base": "selpres.report.groups",
    "SETS": "selpres.report.groups",
    "UNITS": "selpres.report.groups",
    "Options": "selpres.report.compare",
    "Margin": "selpres.report.compare",
    "ALPHA": "selpres.report.compare",
    "paired": "selpres.report.compare",
    "paired_columns": "selpres.report.compare",
    "outcome": "selpres.report.compare",
    "reading": "selpres.report.compare",
    "adjust_family": "selpres.report.compare",
    "comparisons": "selpres.report.compare",
    "mean_curve": "selpres.report.compare",
    "reach": "selpres.report.compare",
    "time_to_target_rows": "selpres.report.compare",
    "summarize": "selpres.run.stats",
    "median": "selpres.run.stats",
    "tost": "selpres.run.stats",
    "trimmed": "selpres.run.stats",
    "holm": "selpres.run.stats",
    "clopper_pearson": "selpres.run.stats",
    "mcnemar_exact": "selpres.run.stats",
    "is_stalled": "selpres.run.stalls",
    "verdict": "selpres.report.sections.verdict",
    "time_to_target": "selpres.report.sections.time_to_target",
    "pyplot": "selpres.report.sections.plots",
    "save_png": "selpres.report.sections.plots",
    "draw_cost": "selpres.report.sections.plots",
    "draw_curves": "selpres.report.sections.plots",
    "Side": "selpres.report.sections.plots",
    "family_styles": "selpres.report.sections.plots",
    "nm_log_axis": "selpres.report.sections.plots",
    "thousands": "selpres.report.sections.plots",
    "table": "selpres.report.markdown",
    "fmt": "selpres.report.markdown",
    "ci": "selpres.report.markdown",
    "mean_std": "selpres.report.markdown",
    "signed_interval": "selpres.report.markdown",
    "diff_text": "selpres.report.markdown",
    "pvalues_text": "selpres.report.markdown",
    "engine_text": "selpres.report.markdown",
}
_MODULES = {"verdict", "time_to_target"}  # blocks exported as their modules

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'selpres.report' has no attribute {name!r}")
    module = importlib.import_module(_EXPORTS[name])
    value = module if name in _MODULES else getattr(module, name)
    globals()[name] = value  # once imported, a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
