"""What every report section reads (:class:`Context`), what it gives back (:class:`Section`), and what a section's
README block reads of the built report (:class:`Built`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from omegaconf import OmegaConf

from selpres.report.compare import Options
from selpres.report.groups import Group, aggregate
from selpres.report.jobs import Job, load_jobs


@dataclass
class Context:
    """A sweep, loaded and grouped once for all sections; ``order``: the order of the methods' rows, a study's
    (:func:`selpres.report.plugins.study_order`), the methods it does not list after them by name."""

    sweep: Path
    jobs: list[Job]
    groups: dict[tuple[str, str], Group]
    topologies: list[str]
    methods: list[str]
    options: Options = field(default_factory=Options)
    experiment: str | None = None  # the study the sweep ran (``experiment=NAME``), None when it names none
    order: tuple[str, ...] = ()

    @classmethod
    def load(cls, sweep: Path, options: Options | None = None, order: tuple[str, ...] = ()) -> Context:
        jobs = load_jobs(sweep)
        return cls(
            sweep,
            jobs,
            *aggregate(jobs, order),
            options=options or Options(),
            experiment=experiment_of(sweep),
            order=tuple(order),
        )

    @property
    def warnings(self) -> list[str]:
        return [w for g in self.groups.values() for w in g.warnings]


def multirun_hydra(sweep: Path):
    """The ``hydra`` node of the sweep's ``multirun.yaml`` (what Hydra recorded of the sweep), or None for folders
    gathered by hand (or an unreadable file)."""
    try:
        return OmegaConf.load(sweep / "multirun.yaml").hydra
    except Exception:
        return None


def experiment_of(sweep: Path) -> str | None:
    """The experiment a sweep ran, as Hydra recorded its choice (``hydra.runtime.choices.experiment``); None for
    folders gathered by hand or a sweep without one."""
    hydra = multirun_hydra(sweep)
    name = None if hydra is None else OmegaConf.select(hydra, "runtime.choices.experiment")
    return str(name) if name else None


@dataclass
class Section:
    """One ``##`` section of report.md: its Markdown blocks, the CSV files behind them (file name -> rows)
    and its figures (file name -> (caption, draw(path))). A study's section may also give the report its title
    (``heading``; the first section's that has one) and the README block ``--readme`` writes (``readme(report,
    command)``: the block's Markdown, from the built report; the command that made it is named in it)."""

    title: str
    blocks: list[str]
    csv: dict[str, list[dict]] = field(default_factory=dict)
    figures: dict[str, tuple[str, Callable[[Path], None]]] = field(default_factory=dict)
    heading: str | None = None
    readme: Callable[[Built, str], str] | None = None

    def markdown(self) -> str:
        return "\n\n".join([f"## {self.title}", *self.blocks])


class Built(Protocol):
    """What a section's ``readme`` reads of the built report (:class:`selpres.report.build.Report` is one): the
    sweep's context and the rows behind any section's CSV file."""

    ctx: Context
    sections: list[Section]

    def rows(self, csv_name: str) -> list[dict]: ...
