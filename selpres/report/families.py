"""Families: one method with its critical parameters swept, the unit of the sensitivity study (issue 10).

A *setting* is one (topology, method) group. Its family is what remains when the swept parameters are
set aside:

- the schedule's kind: one stage = conventional training; several stages grown in the paper's stratified
  order = selective presentation; several stages in another order = staged training in that order;
- the optimizer, ``optim.name`` (results written before optimizers could be chosen have none: the paper's
  SGD with momentum, "paper").

One-stage families are also split by total presentations: a rival is tuned at a fixed cost (the paper's
150,300 or selective's 70,560), and lr × momentum at two costs are two questions. Staged families are not
split: N_i and n_i change the cost by design, and the spread of costs is printed beside them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from selpres.report.groups import Group, setting_text, settings, varying
from selpres.report.paper import PAPER, PAPER_OPTIM

SELECTIVE = "selective presentation"
PAPER_ORDER = "stratified"
SCHEDULE = "schedule."  # the keys of p, n_i, N_i (and order, budget): selective presentation's parameters


def optimizer(g: Group) -> str:
    """``optim.name`` of the group's jobs; "paper" (SGD with momentum) when the config has none."""
    return ((g.used[0].results.get("config") or {}).get("optim") or {}).get("name") or "paper"


def stages(g: Group) -> int:
    return len(g.sched["sizes"])


def family_name(g: Group) -> str:
    """The family of a setting (see the module's docstring), e.g. "selective presentation",
    "conventional SGD at 150,300 t", "quickprop at 70,560 t", "staged, random order"."""
    opt = optimizer(g)
    if stages(g) == 1:
        return f"{'conventional SGD' if opt == 'paper' else opt} at {g.sched['presentations']:,} t"
    order = g.sched.get("order") or PAPER_ORDER
    name = SELECTIVE if order == PAPER_ORDER else f"staged, {order} order"
    return name if opt == "paper" else f"{name} with {opt}"


@dataclass
class Family:
    """The settings of one family in one topology; ``settings[method]``: the flat config of that setting."""

    name: str
    topology: str
    members: list[Group]
    settings: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def keys(self) -> list[str]:
        """The swept parameters: the config keys whose value differs between the family's settings."""
        return varying(list(self.settings.values()))

    def label(self, g: Group) -> str:
        """A setting named by the swept parameters alone ("optim.lr=0.1 schedule.sizes=[…]")."""
        return setting_text(self.settings[g.schedule], self.keys) or g.schedule

    def values(self, key: str) -> list[str]:
        """The values a swept parameter took, sorted numerically where they are numbers ("absent" where a
        setting's config lacks the key)."""
        seen = {f.get(key, "absent") for f in self.settings.values()}
        return sorted(seen, key=_sort_key)

    def ranges(self) -> dict[str, list[str]]:
        return {k: self.values(k) for k in self.keys}

    def ranges_text(self) -> str:
        """"optim.lr ∈ {0.1, 0.15, 0.3}; schedule.sizes ∈ {…}": the ranges a verdict depends on."""
        return "; ".join(f"{k} ∈ {{{', '.join(v.replace(chr(34), '') for v in vals)}}}"
                         for k, vals in self.ranges().items())

    def presentations(self) -> tuple[int, int]:
        costs = [g.sched["presentations"] for g in self.members]
        return min(costs), max(costs)


def _sort_key(text: str) -> tuple:
    try:
        v = json.loads(text)
    except (TypeError, ValueError):
        return (2, text)
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return (0, v, text)
    if isinstance(v, list) and all(isinstance(x, (int, float)) for x in v):
        return (1, v, text)
    return (2, text)


def family_rank(name: str) -> tuple:
    """Selective presentation first, then conventional SGD, then the rest by name."""
    return (not name.startswith(SELECTIVE), not name.startswith("conventional SGD"), name)


def families(groups: dict[tuple[str, str], Group], topologies: list[str]) -> list[Family]:
    """Every family of every topology, settings in method order; groups without results are left out."""
    out: dict[tuple[str, str], Family] = {}
    for (t, m), g in groups.items():
        if g.sched is None:
            continue
        fam = out.setdefault((t, family_name(g)), Family(family_name(g), t, []))
        fam.members.append(g)
        fam.settings[m] = settings(g.used[0])
    return sorted(out.values(), key=lambda f: (topologies.index(f.topology), family_rank(f.name)))


def at_fixed_other_parameters(fam: Family) -> list[Family]:
    """A staged family swept over its schedule *and* other keys (e.g. the learning rate), split into one
    family per value of the other keys: the paper's sentence is about p, N_i and n_i alone, so their
    spread is also read with everything else held fixed. Only parts with two or more settings."""
    keys = fam.keys
    others = [k for k in keys if not k.startswith(SCHEDULE)]
    if stages(fam.members[0]) == 1 or not others or len(others) == len(keys):
        return []
    parts: dict[str, Family] = {}
    for g in fam.members:
        fixed = setting_text(fam.settings[g.schedule], others)
        part = parts.setdefault(fixed, Family(f"{fam.name} at {fixed}", fam.topology, []))
        part.members.append(g)
        part.settings[g.schedule] = fam.settings[g.schedule]
    return [p for p in parts.values() if len(p.members) > 1]


def _is_paper_optim(g: Group) -> bool:
    optim = (g.used[0].results.get("config") or {}).get("optim") or {}
    return optimizer(g) == "paper" and all(optim.get(k) == v for k, v in PAPER_OPTIM.items() if k != "name")


def paper_conventional(groups: dict[tuple[str, str], Group], topology: str) -> Group | None:
    """The run whose final error is the time-to-target target: the paper's conventional method (all n
    patterns, 150 epochs, SGD with the paper's lr and momentum). Without one, the single one-stage SGD run
    of 150 epochs, if there is exactly one; else None (no target: the report says so)."""
    ref = PAPER["conventional"]
    candidates = [g for (t, _), g in sorted(groups.items()) if t == topology and g.sched is not None
                  and optimizer(g) == "paper" and g.sched["sizes"] == ref["sizes"]
                  and g.sched["epochs"] == ref["epochs"] and g.sched["presentations"] == ref["presentations"]]
    exact = [g for g in candidates if _is_paper_optim(g)]
    if len(exact) == 1:
        return exact[0]
    return candidates[0] if len(candidates) == 1 else None
