"""What every report section reads (:class:`Context`) and what it gives back (:class:`Section`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import OmegaConf

from selpres.report.compare import Options
from selpres.report.groups import Group, aggregate
from selpres.report.jobs import Job, load_jobs
from selpres.report.paper import PAPER


@dataclass
class Context:
    """A sweep, loaded and grouped once for all sections."""

    sweep: Path
    jobs: list[Job]
    groups: dict[tuple[str, str], Group]
    topologies: list[str]
    methods: list[str]
    options: Options = field(default_factory=Options)
    experiment: str | None = None  # the study the sweep ran (``experiment=NAME``), None when it names none

    @classmethod
    def load(cls, sweep: Path, options: Options | None = None) -> Context:
        jobs = load_jobs(sweep)
        return cls(sweep, jobs, *aggregate(jobs), options=options or Options(), experiment=experiment_of(sweep))

    @property
    def table1_like(self) -> bool:
        """Whether the sweep is Table 1's grid: the paper's methods (with our matched and random growth), one
        setting each per topology. A sweep that labels its methods by swept settings (a study of parameters)
        is not, and its report leads with the sections it is about."""
        return any(m in PAPER for m in self.methods) and all(" " not in m for m in self.methods)

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
    and its figures (file name -> (caption, draw(path)))."""

    title: str
    blocks: list[str]
    csv: dict[str, list[dict]] = field(default_factory=dict)
    figures: dict[str, tuple[str, Callable[[Path], None]]] = field(default_factory=dict)

    def markdown(self) -> str:
        return "\n\n".join([f"## {self.title}", *self.blocks])
