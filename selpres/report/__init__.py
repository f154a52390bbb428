"""A sweep's report from its ``results.json`` files: the shared blocks every study's section is made of, and the
report that puts the studies' sections together (:mod:`selpres.studies`: Table 1, modern, selection, sensitivity).

    python -m selpres.report outputs/sweeps/table1 [--out DIR]     (default DIR = <sweep>/report)
    python -m selpres.report outputs/sweeps/table1 --readme README.md   (also the block its study writes there)
    python -m selpres.report outputs/sweeps/table1 --margin 5% --holm   (equivalence margin, Holm)

The package reads in the data's direction, one concern per module:

- ``jobs``      every job folder under the sweep (finished, diverged, failed, missing or unreadable);
- ``validate``  what the report reads of a results.json, checked at load (wrong types: unreadable; NaN: missing);
- ``groups``    method labels (what the jobs recorded), and the replicas of each (topology, method) pooled by seed;
- ``compare``   paired differences by seed and their readings, mean curves, time to target;
- ``markdown``  number formats, Markdown tables and CSV text;
- ``context``   what every section reads (the sweep loaded once, the experiment it ran, a study's order of rows)
  and gives back;
- ``sections/`` blocks a study composes: verdicts against a reference, time to target, figures of error against
  cost; and the one generic section, the runs;
- ``build``     the report: the sections of the studies that apply (found in :mod:`selpres.studies` by a registry,
  never imported here), then the runs, written to the output folder;
- ``readme``    a README's generated block (between ``<!-- table1:begin/end -->``), rewritten from the report;
- ``__main__``  the command line.

Conventions: diverged replicas are left out of every mean and interval but counted; comparisons with a reference
method are paired by seed (only seeds complete in both); intervals are Student-t 95 % intervals from
:mod:`selpres.run.stats`; a verdict reads *better/worse*, *equivalent within ±m* (TOST) or *no detectable
difference*, three different things.

The report is the last stage of arm -> data -> presentation -> engine -> loop -> results -> report: it reads job
folders, never trains. What a study is about (which method is the reference, which runs are targets, the order
of rows, a paper's numbers) is the study's, in :mod:`selpres.studies`, the room after this one; nothing here names
a study's arms or methods: a block takes them as arguments, or reads them from the jobs' results.json.
May import: ``selpres.run`` (stats, the names of a job folder's files) and the foundation, never
``selpres.studies`` (the registry ``build.STUDIES`` finds them by name); matplotlib only inside the plotting
sections, so the command line starts without it.
"""

from selpres.report.build import write_report
from selpres.report.groups import aggregate
from selpres.report.jobs import load_jobs

__all__ = ["aggregate", "load_jobs", "write_report"]
