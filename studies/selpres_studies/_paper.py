"""The paper's Table 1 as the Table 1 study's design holds it (``table1.yaml``): the roles of the methods, their
order, what the paper printed, its optimizer and order of growth; and whether a schedule is the paper's. Read by
the Table 1 study and by the studies of the paper's methods (sensitivity, selection: their families, ``_families``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from selpres.report import base
from selpres_studies._design import read_design

DESIGN_FILE = Path(__file__).with_name("table1.yaml")


@dataclass(frozen=True)
class Design:
    """Table 1's roles and the paper's numbers (``table1.yaml``): the *reference* (compared with every other
    method, a time-to-target target), the *baseline* (the other target, and the cost the others' are fractions of),
    the rows' order, short names, what the methods the paper lacks borrow, the families' names and ``paper`` (its
    growth order, optimizer and Table 1 as printed: ``paper["methods"][name]`` = p, sizes, epochs, presentations,
    printed, rms)."""

    reference: str
    baseline: str
    order: tuple[str, ...] = ()
    short: dict = field(default_factory=dict)
    not_in_paper: dict = field(default_factory=dict)
    families: dict = field(default_factory=dict)
    paper: dict = field(default_factory=dict)

    @classmethod
    def load(cls, path: Path = DESIGN_FILE) -> Design:
        return read_design(cls, path)

    @property
    def published(self) -> dict[str, dict]:
        """The paper's methods as Table 1 prints them, by name."""
        return self.paper["methods"]

    def methods(self, found) -> list[str]:
        """The methods of a sweep in the rows' order: the listed ones first, then the others by name."""
        found = set(found)
        listed = [m for m in self.order if m in found]
        return listed + sorted(found - set(listed))


DESIGN = Design.load()


def _stages(sched: dict, method: str) -> bool:
    ref = DESIGN.published[method]
    return (sched["sizes"], sched["epochs"]) == (ref["sizes"], ref["epochs"])


def paper_setting(method: str, sched: dict | None) -> str:
    """Whether a schedule is the paper's: "yes"/"no" for the paper's methods; a method the paper does not have says
    whose setting it borrows (the reference's budget or stages, :data:`Design.not_in_paper`); any other "n/a"."""
    if sched is None:
        return ""
    name, ref = base(method), DESIGN.reference  # a labelled variant ("<name> schedule.sizes=[…]") is still <name>
    borrowed = DESIGN.not_in_paper.get(name)
    if borrowed and borrowed["borrows"] == "budget":
        if sched["presentations"] == DESIGN.published[ref]["presentations"]:
            return f"not in paper ({ref}'s budget)"
        return f"not in paper (budget {sched['presentations']:,}t, not {ref}'s)"
    if borrowed and borrowed["borrows"] == "stages":
        if _stages(sched, ref):
            return f"not in paper ({ref}'s stages, {borrowed['differs']})"
        return f"not in paper ({borrowed['differs']}, other stages than {ref}'s)"
    if name not in DESIGN.published:
        return "n/a"
    return "yes" if _stages(sched, name) else "no"
