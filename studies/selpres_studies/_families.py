"""Families: one method with its critical parameters swept, the unit of the sensitivity study (issue 10), in the
paper's words (Table 1's design, ``table1.yaml``: the two methods' names, the paper's optimizer and order).

A *setting* is one (topology, method) group. Its family is what remains when the swept parameters are
set aside:

- the schedule's kind: one stage = conventional training; several stages grown in the paper's
  order = selective presentation; several stages in another order = staged training in that order;
- the optimizer, ``optim._target_`` (``optim.name`` in results written before it; none in results written
  before optimizers could be chosen: the paper's SGD with momentum, "paper").

One-stage families are also split by total presentations: a rival is tuned at a fixed cost (the paper's
150,300 or selective's 70,560), and lr × momentum at two costs are two questions. Staged families are not
split: N_i and n_i change the cost by design, and the spread of costs is printed beside them. A one-stage
run that is alone at its cost and is the *budget-matched partner* of a staged run (the same presentations
within 1 %, the same other settings) belongs to the family "<optimizer>, budget-matched": conventional
training stopped at each staged run's cost is one method swept over its budget, not one family per cost.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from selpres.report import Group, optim_target, presents_all, setting_text, settings, varying
from selpres_studies._paper import DESIGN

PAPER, PAPER_OPTIM = DESIGN.published, DESIGN.paper["optim"]
SELECTIVE = DESIGN.families["staged"]  # "selective presentation"
CONVENTIONAL_SGD = DESIGN.families["one_stage"]  # "conventional SGD"
BUDGET_MATCHED = "budget-matched"
PAPER_ORDER = DESIGN.paper["growth"]  # "stratified"
SCHEDULE = "schedule."  # the keys of p, n_i, N_i (and order, budget): selective presentation's parameters
SGD = PAPER_OPTIM["_target_"]  # optim._target_ of SGD with momentum (configs/optim/paper.yaml)
# how results written before named SGD: optim.name "paper", or no name at all
_SGD_NAMES = (SGD, *DESIGN.paper["optim_before"])
BUDGET_TOLERANCE = 0.01  # a one-stage run within 1 % of a staged run's presentations is budget-matched


def optimizer(g: Group) -> str:
    """The optimizer of the group's jobs; SGD with momentum is "sgd" whatever name older results gave it."""
    name = optim_target((g.used[0].results.get("config") or {}).get("optim") or {})
    return SGD if name in _SGD_NAMES else name


def stages(g: Group) -> int:
    return len(g.sched["sizes"])


def _method(g: Group) -> str:
    """How one-stage training with the group's optimizer is named: "conventional SGD", "quickprop", ..."""
    return CONVENTIONAL_SGD if optimizer(g) == SGD else optimizer(g)


def family_name(g: Group) -> str:
    """The family of a setting (see the module's docstring) before budget-matched runs are gathered, e.g.
    "selective presentation", "conventional SGD at 150,300 t", "quickprop at 70,560 t", "staged, random
    order"."""
    if stages(g) == 1:
        return f"{_method(g)} at {g.cost:,} t"
    order = g.sched.get("order") or PAPER_ORDER
    name = SELECTIVE if order == PAPER_ORDER else f"staged, {order} order"
    return name if optimizer(g) == SGD else f"{name} with {optimizer(g)}"


def _rest(g: Group) -> dict[str, str]:
    """A setting's config outside ``schedule.*``: what a budget-matched partner must share."""
    return {k: v for k, v in settings(g.used[0]).items() if not k.startswith(SCHEDULE)}


def same_cost(a: float, b: float) -> bool:
    """Whether two costs in presentations are one budget (within :data:`BUDGET_TOLERANCE`)."""
    return abs(a / b - 1) <= BUDGET_TOLERANCE


def pruned(g: Group) -> bool:
    """A data-pruning run (InfoBatch, Selective Backprop): one stage, but not conventional training."""
    return bool(g.used) and pruned_job(g.used[0].results)


def pruned_job(res: dict) -> bool:
    """A job that chose within its one stage (a pruning policy, a user's selector): not conventional training."""
    return len(res["schedule"]["sizes"]) == 1 and not presents_all(res)


def matched_partner(groups: dict[tuple[str, str], Group], g: Group) -> Group | None:
    """The one-stage conventional run of the same topology and settings (outside the schedule) whose
    presentations are closest to ``g``'s, if within 1 %; None if there is none."""
    cost, rest = g.cost, _rest(g)
    candidates = [
        h
        for (t, _), h in groups.items()
        if t == g.topology
        and h.sched is not None
        and stages(h) == 1
        and not pruned(h)
        and same_cost(h.cost, cost)
        and _rest(h) == rest
    ]
    return min(candidates, key=lambda h: (abs(h.cost - cost), h.schedule), default=None)


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
        """ "optim.lr ∈ {0.1, 0.15, 0.3}; schedule.sizes ∈ {…}": the ranges a verdict depends on."""
        return "; ".join(f"{k} ∈ {{{', '.join(map(_shown, vals))}}}" for k, vals in self.ranges().items())

    def swept_text(self) -> str:
        """The ranges in the paper's words: a staged family's schedules as p, n_1, the growth of n_i, the
        profile of N_i and the total N = ΣN_i (the terms that vary), then its other swept keys; a one-stage
        family's keys as :meth:`ranges_text`."""
        if stages(self.members[0]) == 1:
            return self.ranges_text()
        terms = [schedule_terms(g.sched) for g in self.members]
        parts = [
            f"{name} ∈ {{{', '.join(map(str, vals))}}}"
            for name in terms[0]
            if len(vals := sorted({t[name] for t in terms}, key=_term_rank)) > 1
        ]
        parts += [
            f"{k} ∈ {{{', '.join(_shown(v) for v in self.values(k))}}}" for k in self.keys if not k.startswith(SCHEDULE)
        ]
        return "; ".join(parts)

    def presentations(self) -> tuple[int, int]:
        costs = [g.cost for g in self.members]
        return min(costs), max(costs)


def _shown(value: str) -> str:
    """A config value as the report prints it: strings unquoted, null (the key not set) as "not set"."""
    return "not set" if value == "null" else value.replace('"', "")


def _term_rank(v) -> tuple:
    return (0, v, "") if isinstance(v, (int, float)) else (1, 0, str(v))


def _growth(sizes: list[int]) -> str:
    """How the stage sizes n_i grow: the paper's (its n_2 … n_p after any n_1), geometric (a constant
    ratio, to the rounding of whole patterns), linear (a constant step, to the rounding) or other."""
    if len(sizes) == 2:
        return "one step"
    if sizes[1:] == PAPER[DESIGN.reference]["sizes"][1:]:
        return "the paper's"
    ratios = [b / a for a, b in zip(sizes, sizes[1:])]
    steps = [b - a for a, b in zip(sizes, sizes[1:])]
    if max(ratios) / min(ratios) - 1 <= 0.02:
        return "geometric"
    if max(steps) - min(steps) <= 1:
        return "linear"
    return "other"


def _profile(epochs: list[int]) -> str:
    """The profile of the epochs per stage N_i: equal (to the rounding of a total that does not divide),
    increasing, decreasing or mixed."""
    if max(epochs) - min(epochs) <= 1:
        return "equal"
    if all(a <= b for a, b in zip(epochs, epochs[1:])):
        return "increasing"
    if all(a >= b for a, b in zip(epochs, epochs[1:])):
        return "decreasing"
    return "mixed"


def schedule_terms(sched: dict) -> dict:
    """A staged schedule in the paper's terms (section 3): p, n_1, the growth of n_i, the profile of N_i
    and the total number of epochs N = ΣN_i."""
    return {
        "p": sched["p"],
        "n_1": sched["sizes"][0],
        "n_i growth": _growth(sched["sizes"]),
        "N_i profile": _profile(sched["epochs"]),
        "N = ΣN_i": sum(sched["epochs"]),
    }


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
    """Selective presentation first, then conventional SGD budget-matched to it, then conventional SGD at
    fixed costs, then the rest by name."""
    return (
        not name.startswith(SELECTIVE),
        name != f"{CONVENTIONAL_SGD}, {BUDGET_MATCHED}",
        not name.startswith(CONVENTIONAL_SGD),
        name,
    )


def families(groups: dict[tuple[str, str], Group], topologies: list[str]) -> list[Family]:
    """Every family of every topology, settings in method order; groups without results are left out.
    One-stage runs alone at their cost that are a staged run's budget-matched partner are gathered into
    "<optimizer>, budget-matched" (see the module's docstring)."""
    done = {k: g for k, g in groups.items() if g.sched is not None}
    partners = {id(p) for g in done.values() if stages(g) > 1 and (p := matched_partner(done, g))}
    by_name: dict[tuple[str, str], list[Group]] = {}
    for (t, _), g in done.items():
        by_name.setdefault((t, family_name(g)), []).append(g)
    out: dict[tuple[str, str], Family] = {}
    for (t, name), members in by_name.items():
        for g in members:
            alone = len(members) == 1 and stages(g) == 1 and id(g) in partners
            fam_name = f"{_method(g)}, {BUDGET_MATCHED}" if alone else name
            fam = out.setdefault((t, fam_name), Family(fam_name, t, []))
            fam.members.append(g)
            fam.settings[g.schedule] = settings(g.used[0])
    return sorted(out.values(), key=lambda f: (topologies.index(f.topology), family_rank(f.name)))


def at_paper_total_epochs(fam: Family) -> Family | None:
    """A staged family whose total epochs N = ΣN_i vary, restricted to the paper's N (150): N changes the
    cost, and a longer run is better for any method, so the spread over p, n_i and the profile of N_i is
    also read at the paper's total. None unless two or more settings have it and some have another N."""
    total = sum(PAPER[DESIGN.reference]["epochs"])
    if stages(fam.members[0]) == 1:
        return None
    at = [g for g in fam.members if sum(g.sched["epochs"]) == total]
    if len(at) < 2 or len(at) == len(fam.members):
        return None
    return Family(f"{fam.name} at ΣN_i = {total}", fam.topology, at, {g.schedule: fam.settings[g.schedule] for g in at})


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
    return optimizer(g) == SGD and all(optim.get(k) == v for k, v in PAPER_OPTIM.items() if k != "_target_")


def paper_run(groups: dict[tuple[str, str], Group], topology: str, method: str) -> Group | None:
    """The paper's ``method`` (one of Table 1's, :data:`PAPER`) in one topology: its n_i and N_i (Table 1),
    grown in the paper's order, trained by SGD with the paper's lr and momentum (Note 1 of Table 1). Without
    one, the single SGD run with the paper's stages, if there is exactly one; else None."""
    ref = PAPER[method]
    candidates = [
        g
        for (t, _), g in sorted(groups.items())
        if t == topology
        and g.sched is not None
        and optimizer(g) == SGD
        and g.sched["sizes"] == ref["sizes"]
        and g.sched["epochs"] == ref["epochs"]
        and g.sched["presentations"] == ref["presentations"]
        and (stages(g) == 1 or (g.sched.get("order") or PAPER_ORDER) == PAPER_ORDER)
    ]
    exact = [g for g in candidates if _is_paper_optim(g)]
    if len(exact) == 1:
        return exact[0]
    return candidates[0] if len(candidates) == 1 else None


def paper_conventional(groups: dict[tuple[str, str], Group], topology: str) -> Group | None:
    """The run whose final error is the time-to-target target and whose learning curve is the error–cost
    plane's frontier: the paper's conventional method (all n patterns, 150 epochs, SGD with lr 0.15 and
    momentum 0.9); else the single one-stage SGD run of 150 epochs; else None (the report says so)."""
    return paper_run(groups, topology, DESIGN.baseline)
