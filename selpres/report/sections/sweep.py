"""The sweep section: which setting of a sweep, at what cost, how sure, in the sweep's own keys.

Read from the jobs alone (no study names): a *setting* is one (topology, method) group of the sweep; the one-stage
conventional runs of schedule names that never stage (the partners ``partners=on`` adds, or ``matched`` and
``conventional`` presets) are its *conventional runs*, unless every group is one stage (then each is a setting).
Each setting is compared, paired by seed on the final held-out RMS, with

- its *compute-matched partner*: the conventional run of the same other settings (outside ``schedule.*``) and the
  same cost within :data:`SAME_COST` (training plus the charge for choosing), and
- *conventional training*: the longest conventional run of whole epochs with the same other settings;

each comparison is read by :mod:`selpres.report.compare` (better / worse / equivalent within ±m / no detectable
difference), its p-values Holm-adjusted over its family (all settings against their partners; all against
conventional training). "Best" is never the lowest error alone: the *Pareto set* on (cost, mean error) over every
point (conventional runs included), a dominated setting whose 95 % interval reaches the front at its cost marked
*not resolved*; and, with ``--budget``, the lowest mean error among the settings that cost at most that. A sweep
without its partners names them and prints the one command that adds them (:func:`selpres.run.partners.rerun_command`).
Figures: :mod:`selpres.report.sections.sweep_plots`.
"""

from __future__ import annotations

from selpres.report.compare import Options, adjust_family, mean_curve, outcome, paired, paired_columns, reading
from selpres.report.context import Context, Section
from selpres.report.groups import Group, base, presents_all, replica_costs, settings, varying
from selpres.report.markdown import fmt, signed_interval, table
from selpres.report.sections import sweep_plots
from selpres.report.sections.sweep_plots import Point, number
from selpres.run.stats import summarize

SAME_COST = 0.01  # a conventional run within 1 % of a setting's presentations is its compute-matched partner
SCHEDULE = "schedule."


def one_stage(g: Group) -> bool:
    """Conventional training: one stage, every pattern presented (selpres.report.groups.presents_all)."""
    return presents_all(g.used[0].results)


def _rest(g: Group) -> dict[str, str]:
    """A group's settings outside the schedule: what a partner must share."""
    return {k: v for k, v in settings(g.used[0]).items() if not k.startswith(SCHEDULE)}


def _whole_epochs(g: Group) -> bool:
    return not any(g.sched.get("extra_presentations") or [])


def roles(groups: dict) -> tuple[list[Group], list[Group]]:
    """(settings, conventional runs) of a sweep (see the module's docstring)."""
    done = [g for g in groups.values() if g.sched is not None and g.used]
    staged = {base(g.schedule) for g in done if not one_stage(g)}
    if not staged:
        return done, []
    conventional = [g for g in done if one_stage(g) and base(g.schedule) not in staged]
    return [g for g in done if g not in conventional], conventional


def partner_of(g: Group, conventional: list[Group]) -> Group | None:
    """The compute-matched partner: same topology and other settings, the cost within :data:`SAME_COST`."""
    rest = _rest(g)
    near = [
        h
        for h in conventional
        if h.topology == g.topology and abs(h.cost / g.cost - 1) <= SAME_COST and _rest(h) == rest
    ]
    return min(near, key=lambda h: abs(h.cost - g.cost), default=None)


def full_run(g: Group, conventional: list[Group]) -> Group | None:
    """Conventional training: the longest run of whole epochs with the same topology and other settings."""
    rest = _rest(g)
    runs = [h for h in conventional if h.topology == g.topology and _whole_epochs(h) and _rest(h) == rest]
    return max(runs, key=lambda h: h.cost, default=None)


def swept_keys(members: list[Group]) -> list[str]:
    """The keys the settings differ in, the schedule's name first where it varies; keys that only follow the name
    (a preset's sizes) left out."""
    flat = {id(g): settings(g.used[0]) for g in members}
    keys = varying(list(flat.values()))
    names = {base(g.schedule) for g in members}
    if len(names) > 1:
        within = set()
        for name in names:
            within |= set(varying([flat[id(g)] for g in members if base(g.schedule) == name]))
        keys = ["schedule.name", *[k for k in keys if k in within]]
    return keys


def _shown(text: str | None) -> str:
    return "—" if text in (None, "null") else str(text).replace('"', "")


def value_of(g: Group, key: str) -> str:
    return _shown(settings(g.used[0]).get(key))


def title_of(keys: list[str], members: list[Group]) -> str:
    """What the sweep varied, in its own keys: "Sweep over schedule.p × schedule.first"."""
    if not keys:
        return "Sweep: one setting"
    if keys[0] == "schedule.name":
        names = ", ".join(dict.fromkeys(base(g.schedule) for g in members))
        return "Sweep over schedule (" + names + ")" + "".join(f" × {k}" for k in keys[1:])
    return "Sweep over " + " × ".join(keys)


def pareto(points: list[Point]) -> dict[int, str]:
    """id(group) -> "Pareto" / "dominated" / "not resolved" over (cost, mean error); a dominated point whose 95 %
    interval reaches below the lowest mean error of the points costing no more is not resolved."""
    scored = [p for p in points if p.stats["mean"] is not None]
    out = {}
    for p in scored:
        c, e = p.cost, p.stats["mean"]
        others = [q for q in scored if q is not p and q.cost <= c]
        dominated = any(q.stats["mean"] <= e and (q.cost < c or q.stats["mean"] < e) for q in others)
        if not dominated:
            out[id(p.group)] = "Pareto"
            continue
        front = min(q.stats["mean"] for q in others)
        lo = p.stats["ci95"][0]
        out[id(p.group)] = "not resolved" if lo is not None and lo <= front else "dominated"
    return out


def sweep_rows(ctx: Context) -> tuple[list[dict], list[Point], list[Point], list[str]]:
    """(one row per setting, the settings' points, the conventional runs' points, the swept keys)."""
    members, conventional = roles(ctx.groups)
    keys = swept_keys(members)
    order = lambda g: [number(settings(g.used[0]).get(k, "null")) for k in keys]
    members.sort(key=lambda g: (ctx.topologies.index(g.topology), [(isinstance(v, str), v) for v in order(g)]))
    options = Options(margin=ctx.options.margin, holm=True)  # always Holm over each family (the module's docstring)
    points = [Point(g, i + 1, _cost_ci(g)) for i, g in enumerate(members)]
    conv_points = [Point(h, 0, _cost_ci(h)) for h in conventional]
    front: dict[int, str] = {}
    for t in ctx.topologies:
        front.update(pareto([p for p in points + conv_points if p.group.topology == t]))
    rows, families = [], {"partner": [], "full": []}
    for pt in points:
        g, st = pt.group, pt.stats
        row = {"number": pt.number, "topology": g.topology, "setting": g.schedule}
        rows.append(row)
        row.update({k: value_of(g, k) if k != "schedule.name" else base(g.schedule) for k in keys})
        full = full_run(g, conventional)
        conv_cost = full.cost if full is not None else g.sched["conventional_presentations"]
        row.update(
            p=g.sched["p"],
            sizes=" ".join(map(str, g.sched["sizes"])),
            epochs=" ".join(map(str, g.sched["epochs"])) + _partial(g.sched),
            presentations=g.cost,
            presentations_ci_lo=pt.cost_ci[0],
            presentations_ci_hi=pt.cost_ci[1],
            percent_of_conventional=100 * g.cost / conv_cost if conv_cost else None,
            full_basis="the full one-stage run" if full is not None else "T_con at equal epochs",
            seeds=st["n"],
            diverged=g.n_diverged,
            heldout_nm_mean=st["mean"],
            heldout_nm_ci_lo=st["ci95"][0],
            heldout_nm_ci_hi=st["ci95"][1],
            pareto=front.get(id(g), "no results"),
        )
        for role, other in (("partner", partner_of(g, conventional)), ("full", full)):
            if other is None or other is g:
                row[f"{role}_reading"] = "itself" if other is g else f"no {role} run"
                continue
            v = paired(g.values("heldout"), other.values("heldout"), options.margin)
            row.update({f"{role}_run": other.schedule, f"{role}_cost": other.cost})
            row.update(paired_columns(role, v))
            families[role].append((row, v))
    for role, found in families.items():
        adjust_family(found, role, options)
        for row, v in found:
            row[f"{role}_verdict"] = outcome(v)
            row[f"{role}_reading"] = reading({**v, "holm": True}, name=f"#{row['number']}")
    return rows, points, conv_points, keys


def _partial(sched: dict) -> str:
    """A partial last epoch (a budget's leftover), as N_i shows it."""
    extra = sum(sched.get("extra_presentations") or [])
    return f" (+{extra:,} presentations)" if extra else ""


def _cost_ci(g: Group) -> list:
    """The 95 % interval of the cost over seeds where it varies (a pruning policy's), else [None, None]."""
    costs = replica_costs(g.used[0].results)
    st = summarize(costs) if len(set(costs)) > 1 else {"ci95": [None, None]}
    return [st["ci95"][0], st["ci95"][1]]


def _verdict(r: dict, role: str) -> str:
    said = r.get(f"{role}_verdict")
    if said is None:
        return r.get(f"{role}_reading", "")
    d, lo, hi = r[f"{role}_diff_mean"], r[f"{role}_ci_lo"], r[f"{role}_ci_hi"]
    if said == "equivalent":
        said = f"equivalent within ±{r[f'{role}_margin']:.4f}"
    elif said == "no detectable difference" and lo is not None and not lo <= 0 <= hi:
        said += f" after Holm (p = {r[f'{role}_p_holm']:.2g})"
    return f"{d:+.4f} {signed_interval(lo, hi)}: {said}"


def sweep_markdown(rows: list[dict], keys: list[str]) -> str:
    head = ["#", *keys, "p", "n_i", "N_i", "cost (presentations)", "% of full training", "held-out RMS Nm [95 % CI]"]
    head += ["Δ vs partner [95 % CI]: verdict", "Δ vs full training [95 % CI]: verdict", "Pareto"]
    tops = len({r["topology"] for r in rows}) > 1
    head = head[:1] + ["topology"] * tops + head[1:]
    body = []
    for r in rows:
        rms = "no complete seed" if r["heldout_nm_mean"] is None else fmt(r["heldout_nm_mean"])
        if r["heldout_nm_ci_lo"] is not None:
            rms += f" [{fmt(r['heldout_nm_ci_lo'])}, {fmt(r['heldout_nm_ci_hi'])}]"
        rms += f" ({r['seeds']} seeds" + (f", {r['diverged']} diverged)" if r["diverged"] else ")")
        pct = "n/a" if r["percent_of_conventional"] is None else f"{r['percent_of_conventional']:.1f} %"
        cells = [str(r["number"]), *([r["topology"]] if tops else []), *(r[k] for k in keys)]
        cells += [str(r["p"]), r["sizes"], r["epochs"], f"{r['presentations']:,.0f}", pct, rms]
        cells += [_verdict(r, "partner"), _verdict(r, "full"), r["pareto"]]
        body.append(cells)
    return table(head, body)


def best_text(rows: list[dict], budget: int | None) -> str:
    """ "Best" as the Pareto set, and with ``--budget`` the lowest mean error within it."""
    on = [r for r in rows if r["pareto"] == "Pareto"]
    unsure = [r for r in rows if r["pareto"] == "not resolved"]
    name = lambda r: f"#{r['number']} ({r['presentations']:,.0f} t, {fmt(r['heldout_nm_mean'])} Nm)"
    text = (
        "**Best is a trade-off, not one setting.** The Pareto set (no other run, one-stage runs included, costs no "
        f"more and errs no more): {', '.join(map(name, on)) or 'no setting: one-stage runs dominate every one'}."
    )
    if unsure:
        text += (
            f" Not resolved (dominated on the means, its interval reaching the front): {', '.join(map(name, unsure))}."
        )
    if budget is None:
        return text + " Name a cost with `selpres-report DIR --budget N` for the lowest error within it."
    within = [r for r in rows if r["presentations"] <= budget and r["heldout_nm_mean"] is not None]
    if not within:
        return text + f" No setting costs at most {budget:,} presentations (`--budget`)."
    top = min(within, key=lambda r: r["heldout_nm_mean"])
    return text + f" Within {budget:,} presentations (`--budget`): {name(top)}, the lowest mean error there."


def partners_text(ctx: Context, rows: list[dict]) -> str | None:
    """The partners the sweep lacks, and the one command that adds them; None when none is missing."""
    missing = sorted(
        {
            r["presentations"]
            for r in rows
            if r.get("partner_verdict") is None and "itself" not in r.get("partner_reading", "")
        }
    )
    no_full = any(r.get("full_verdict") is None and r.get("full_reading") != "itself" for r in rows)
    if not missing and not no_full:
        return None
    from selpres.run.partners import rerun_command

    what = []
    if missing:
        what.append("one-stage training stopped at " + ", ".join(f"{c:,.0f}" for c in missing) + " presentations")
    if no_full:
        what.append("the full one-stage run (all n patterns, ΣN_i epochs)")
    command = rerun_command(ctx.sweep)
    how = f"`{command}`" if command else "the sweep's command with `partners=on`"
    return (
        f"**Missing partners:** {' and '.join(what)}, so those comparisons are not made. Add them (the sweep's "
        f"jobs are found done): {how}"
    )


NOTE = (
    "Cost: presentations (training plus the charge for choosing A_i), and as a share of the full one-stage run's "
    "(else of T_con = n·ΣN_i at equal epochs). Held-out RMS: final, over all held-out patterns, mean over complete "
    "seeds with its 95 % t-interval. Δ: this setting − the other, paired by seed (negative: this setting errs less); "
    "the verdict is the paired t-test's (better / worse), else two one-sided tests' against ±m (equivalent), else "
    "*no detectable difference*, which does not rule out a real effect of the size its interval allows; p-values "
    "Holm-adjusted within each family (every setting against its partner; every setting against full training). "
    "*Partner*: one-stage training (all n patterns every epoch) stopped at the same cost (within 1 %), the same "
    "other settings; *full training*: the longest such run of whole epochs (the paper's T_con, n·ΣN_i). "
    "*Pareto*: no other run costs no more and errs no more on the means; *not resolved*: dominated on the means, "
    "but its interval reaches the lowest error at its cost."
)


def section(ctx: Context) -> Section | None:
    """The sweep's section, when it has two settings or more and is not a study's (a study's sweep has its own)."""
    if ctx.experiment is not None:
        return None
    rows, points, conv_points, keys = sweep_rows(ctx)
    if len(points) < 2:
        return None
    heading = title_of(keys, [p.group for p in points])
    lines = [best_text(rows, ctx.options.budget), sweep_markdown(rows, keys)]
    lines += [t for t in (partners_text(ctx, rows),) if t]
    curves = {}  # the full one-stage run's learning curve, per topology
    for pt in points:
        full = full_run(pt.group, [c.group for c in conv_points])
        if full is not None and pt.group.topology not in curves:
            curves[pt.group.topology] = mean_curve(full)
    figures, figure_lines = sweep_plots.figures(ctx, rows, points, conv_points, keys, curves)
    margin = ctx.options.margin.describe("the setting")
    lines += [*figure_lines, NOTE + f" Margin m = {margin}."]
    return Section(heading, lines, csv={"sweep.csv": rows}, figures=figures, heading=heading)
