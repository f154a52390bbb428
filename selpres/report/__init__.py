"""Table 1 of the paper from a sweep's ``results.json`` files: tables, verdicts, time-to-target, plots;
and, when the sweep is one, a study's sections (:mod:`selpres.studies`: modern, selection, sensitivity).

    python -m selpres.report outputs/sweeps/table1 [--out DIR]     (default DIR = <sweep>/report)
    python -m selpres.report outputs/sweeps/table1 --readme README.md   (also its Table 1 block)
    python -m selpres.report outputs/sweeps/table1 --margin 5% --holm   (equivalence margin, Holm)

The package reads in the data's direction, one concern per module:

- ``jobs``      every job folder under the sweep (finished, diverged, failed, missing or unreadable);
- ``validate``  what the report reads of a results.json, checked at load (wrong types: unreadable; NaN: missing);
- ``groups``    method labels, and the replicas of each (topology, method) pooled by seed;
- ``paper``     the paper's Table 1 numbers, and whether a schedule is the paper's;
- ``families``  a method with its parameters swept (schedule kind × optimizer), the sensitivity unit;
- ``compare``   paired differences by seed and their readings, mean curves, time to target;
- ``markdown``  number formats, Markdown tables and CSV text;
- ``context``   what every section reads (the sweep loaded once, the experiment it ran) and gives back;
- ``sections/`` the generic sections, one module each, ``section(ctx) -> Section`` (Markdown, CSV rows,
  figures; None when the sweep lacks what it needs): Table 1's grid, verdicts, time to target, plots, runs,
  the error–cost plane;
- ``build``     the report: the sections of the studies that apply (found in :mod:`selpres.studies` by a
  registry, never imported here), then the generic ones, written to the output folder;
- ``readme``    the README's Table 1 block (between ``<!-- table1:begin/end -->``), from the report;
- ``__main__``  the command line.

Conventions: diverged replicas are left out of every mean and interval but counted; comparisons with
``selective`` are paired by seed (only seeds complete in both); intervals are Student-t 95 % intervals
from :mod:`selpres.run.stats`; a verdict reads *better/worse*, *equivalent within ±m* (TOST) or *no
detectable difference*, three different things.

The report is the last stage of arm -> data -> presentation -> engine -> loop -> results -> report: it reads job
folders, never trains. A study's own section (modern, selection, sensitivity) lives in :mod:`selpres.studies`, the
room after this one, and composes the blocks here; nothing here names a study's arms or methods.
May import: ``selpres.run`` (stats, the names of a job folder's files) and the foundation, never
``selpres.studies`` (the registry ``build.STUDIES`` finds them by name); matplotlib only inside the plotting
sections, so the command line starts without it.
"""

from selpres.report.build import write_report
from selpres.report.groups import aggregate
from selpres.report.jobs import load_jobs

__all__ = ["aggregate", "load_jobs", "write_report"]
