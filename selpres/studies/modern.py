"""Modern training and data pruning (issue 22): every method's final held-out error against its total cost, per
arm and training regime, and each against conventional training scheduled for the same cost.

A cell is (arm, regime, method): the arm from ``robot`` (its name, else its file's or its kind), the regime from
the optimizer, its mini-batch and the hidden units (the paper's: sigmoid, online SGD), the method from the
schedule's name the job recorded: a pruning policy no code here knows (SeTa, ...) or a new arm gets its rows as
it is. The study's design (``modern.yaml`` beside this module) names the roles: the *reference* (training at full
cost, compared with nothing) and the *partner*, one-stage conventional training *scheduled* for the same total
cost (its cosine learning rate, where there is one, decays to zero at that budget), against which every other
method of the same arm and regime is compared, paired by seed. The family for Holm's correction is every such
comparison of one metric in the sweep; the readings are the report's three (compare.reading), at the report's
margin (``--margin``, by default 5 % of the method's own mean). nMSE = mean over joints of MSE ÷ the held-out
targets' variance (1 = predicting the mean).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import OmegaConf

from selpres.report.compare import Options, adjust_family, outcome, paired, paired_columns, reading
from selpres.report.context import Context, Section
from selpres.report.families import optim_target
from selpres.report.markdown import table
from selpres.run.stats import summarize

METRICS = (("rms", "held-out RMS", "Nm"), ("nmse", "held-out nMSE", ""))
DODGE = 0.07  # methods of one cost are drawn side by side within ±7 % of their cost
DESIGN_FILE = Path(__file__).with_suffix(".yaml")  # modern.yaml: the study's roles and display names


@dataclass(frozen=True)
class Design:
    """The study's roles and display names (``modern.yaml``): which recorded method is the reference and which the
    compute-matched partner, the rows' order, and how arms, optimizers and activations are shown."""

    reference: str
    partner: str
    order: tuple[str, ...] = ()
    arms: dict = field(default_factory=dict)
    optimizers: dict = field(default_factory=dict)
    activations: dict = field(default_factory=dict)

    @classmethod
    def load(cls, path: Path = DESIGN_FILE) -> Design:
        d = OmegaConf.to_container(OmegaConf.load(path))
        return cls(**{**d, "order": tuple(d.get("order") or ())})

    def methods(self, found) -> list[str]:
        """The methods of a sweep in the rows' order: the listed ones first, then the others by name."""
        found = set(found)
        listed = [m for m in self.order if m in found]
        return listed + sorted(found - set(listed))

    def rivals(self, found) -> list[str]:
        """Every method compared with the partner: all but the reference and the partner itself."""
        return [m for m in self.methods(found) if m not in (self.reference, self.partner)]


DESIGN = Design.load()


def arm_of(cfg: dict, design: Design = DESIGN) -> str:
    r = cfg["robot"]
    key = r.get("name") or (r.get("path") and Path(r["path"]).stem) or r.get("_target_") or r.get("kind")
    return design.arms.get(str(key), str(key))


def regime_of(cfg: dict, design: Design = DESIGN) -> str:
    o, act = cfg["optim"], cfg.get("model", {}).get("activation", "sigmoid")
    name, b = optim_target(o), o["batch_size"]
    if name == "sgd" and b == 1 and act == "sigmoid" and o.get("lr_schedule", "constant") == "constant":
        return f"paper: sigmoid, online SGD (lr {o['lr']:g}, momentum {o.get('momentum') or 0:g})"
    # the rate is left out: it is chosen per arm (on a validation draw), and shown in the table's lr column
    sched = f", {o['lr_schedule']} lr" if o.get("lr_schedule") else ""
    return f"{design.optimizers.get(name, name)} (batch {b}{sched}), {design.activations.get(act, act)}"


@functools.lru_cache(maxsize=8)
def _heldout_variance(robot_json: str, data_json: str) -> tuple[float, ...]:
    import json

    from selpres.data.task import load_task
    from selpres.run.specs import data_spec, robot_spec

    task = load_task(robot_spec(json.loads(robot_json)), data_spec(json.loads(data_json)))
    return tuple(task.tests.heldout.Y.var(0, unbiased=False).tolist())


def heldout_nmse(job) -> dict[int, float]:
    """Per seed, held-out nMSE overall. Reads ``replica_results[r]["final"]["heldout"]["nmse"]["overall"]``
    where results.json holds it (selpres.run.floor, issue 21); else the same quantity from the per-joint RMS
    and the variance of the held-out targets, rebuilt from the job's config (one helper: swap it when every
    results.json carries nMSE)."""
    import json

    out, var = {}, None
    for rep in job.replicas:
        fin = rep["final"]
        if fin is None or fin["heldout"]["nm"].get("overall") is None:
            continue
        if "nmse" in fin["heldout"] and fin["heldout"]["nmse"].get("overall") is not None:
            out[rep["seed"]] = fin["heldout"]["nmse"]["overall"]
            continue
        if var is None:
            cfg = job.results["config"]
            var = _heldout_variance(json.dumps(cfg["robot"], sort_keys=True), json.dumps(cfg["data"], sort_keys=True))
        joints = [k for k in fin["heldout"]["nm"] if k != "overall"]
        per = [fin["heldout"]["nm"][j] ** 2 / v for j, v in zip(joints, var) if v > 0]
        out[rep["seed"]] = sum(per) / len(per)
    return out


@dataclass
class Cell:
    arm: str
    regime: str
    method: str
    costs: list[float] = field(default_factory=list)
    rms: dict[int, float] = field(default_factory=dict)
    nmse: dict[int, float] = field(default_factory=dict)
    engines: set[str] = field(default_factory=set)
    lrs: set[float] = field(default_factory=set)

    @property
    def cost(self) -> float | None:
        return sum(self.costs) / len(self.costs) if self.costs else None

    def values(self, metric: str) -> dict[int, float]:
        return self.rms if metric == "rms" else self.nmse


def job_cost(res: dict) -> float:
    """Total cost in presentations: training plus forward passes charged for choosing (pruning: each replica's
    exact cost, averaged)."""
    if res.get("pruning"):
        c = res["pruning"]["cost"]
        return sum(c) / len(c)
    return res["schedule"]["presentations"] + (res.get("selection_presentations") or 0)


def cells(ctx: Context, design: Design = DESIGN) -> dict[tuple[str, str, str], Cell]:
    """Every finished job's replicas in its (arm, regime, method) cell; the method is the schedule's recorded name."""
    out: dict[tuple[str, str, str], Cell] = {}
    for job in ctx.jobs:
        res = job.results
        if job.status not in ("complete", "diverged") or not res:
            continue
        cfg = res["config"]
        key = (arm_of(cfg, design), regime_of(cfg, design), res["schedule"]["name"])
        c = out.setdefault(key, Cell(*key))
        c.costs.append(job_cost(res))
        c.engines.add(res.get("engine", "?"))
        c.lrs.add(cfg["optim"]["lr"])
        for rep in job.replicas:
            v = rep["final"]["heldout"]["nm"]["overall"] if rep["final"] else None
            if v is not None and math.isfinite(v):
                c.rms[rep["seed"]] = v
        c.nmse.update(heldout_nmse(job))
    return out


def applies(ctx: Context) -> bool:
    """A sweep with a pruning rival or a modern regime beside the paper's."""
    return any(job.results and job.results.get("pruning") for job in ctx.jobs)


def _order(methods: list[str]):
    """Rows by arm, the paper's regime first, then the methods in the design's order."""
    return lambda key: (key[0], not key[1].startswith("paper"), key[1], methods.index(key[2]))


def summary_rows(cs: dict, design: Design = DESIGN) -> list[dict]:
    rows = []
    for key in sorted(cs, key=_order(design.methods(m for _, _, m in cs))):
        c = cs[key]
        row = {
            "arm": c.arm,
            "regime": c.regime,
            "method": c.method,
            "cost": c.cost,
            "lr": ",".join(f"{v:g}" for v in sorted(c.lrs)),
            "engine": ",".join(sorted(c.engines)),
        }
        for metric, _, _ in METRICS:
            s = summarize(c.values(metric).values())
            row.update({f"{metric}_n": s["n"], f"{metric}_mean": s["mean"], f"{metric}_lo": s["ci95"][0]})
            row[f"{metric}_hi"] = s["ci95"][1]
        rows.append(row)
    return rows


def verdict_rows(cs: dict, options: Options, design: Design = DESIGN) -> list[dict]:
    """Every rival against its compute-matched partner, both metrics; Holm over each metric's family."""
    rows, found = [], {m: [] for m, _, _ in METRICS}
    methods = design.methods(m for _, _, m in cs)
    for arm, regime in sorted({(a, r) for a, r, _ in cs}, key=lambda k: _order(methods)((*k, methods[0]))):
        partner = cs.get((arm, regime, design.partner))
        for method in design.rivals(methods):
            c = cs.get((arm, regime, method))
            if c is None or partner is None:
                continue
            row = {"arm": arm, "regime": regime, "comparison": f"{method} − {design.partner}"}
            row["cost_ratio"] = c.cost / partner.cost if partner.cost else None
            for metric, _, _ in METRICS:
                v = paired(c.values(metric), partner.values(metric), options.margin)
                row.update(paired_columns(metric, v))
                found[metric].append((row, v))
            rows.append(row)
    holm = Options(options.margin, holm=True)
    for metric, _, unit in METRICS:
        adjust_family(found[metric], metric, holm)
        for row, v in found[metric]:
            row[f"reading_{metric}"] = reading(
                {**v, "holm": True}, name=row["comparison"].split(" ")[0], unit=unit or ""
            )
    return rows


def _iv(mean, lo, hi, nd=3) -> str:
    if mean is None:
        return "–"
    if lo is None:
        return f"{mean:.{nd}f}"
    return f"{mean:.{nd}f} [{lo:.{nd}f}, {hi:.{nd}f}]"


def summary_markdown(rows: list[dict]) -> str:
    body = [
        [
            r["arm"],
            r["regime"],
            r["method"],
            r["lr"],
            f"{r['cost']:,.0f}" if r["cost"] is not None else "–",
            _iv(r["rms_mean"], r["rms_lo"], r["rms_hi"]),
            _iv(r["nmse_mean"], r["nmse_lo"], r["nmse_hi"], 4),
            str(r["rms_n"]),
        ]
        for r in rows
    ]
    head = [
        "arm",
        "regime",
        "method",
        "lr",
        "total cost (presentations)",
        "held-out RMS, Nm [95 %]",
        "held-out nMSE [95 %]",
        "seeds",
    ]
    return table(head, body)


def verdict_markdown(rows: list[dict]) -> str:
    body = [[r["arm"], r["regime"], r["comparison"], r["reading_rms"], r["reading_nmse"]] for r in rows]
    return table(["arm", "regime", "Δ (paired by seed)", "held-out RMS (Nm)", "held-out nMSE"], body)


def headline(rows: list[dict]) -> str:
    """The counts of each reading after Holm's correction (the adjusted p-values of the rows)."""
    out = []
    for metric, name, _ in METRICS:
        tested = [r for r in rows if r.get(f"{metric}_p_holm") is not None]
        said = [
            outcome(
                {
                    "n": r[f"{metric}_pairs"],
                    "p": r[f"{metric}_p_holm"],
                    "mean": r[f"{metric}_diff_mean"],
                    "p_tost": r.get(f"{metric}_tost_p_holm"),
                }
            )
            for r in tested
        ]
        counts = ", ".join(
            f"{said.count(k)} {k}" for k in ("better", "worse", "equivalent", "no detectable difference")
        )
        out.append(
            f"{name}: of {len(tested)} comparisons with compute-matched training, after Holm's correction {counts}"
        )
    return "**Against compute-matched training** — " + "; ".join(out) + "."


def note(options: Options, design: Design = DESIGN) -> str:
    return (
        "Total cost: back-propagated presentations plus forward passes charged for choosing at "
        "`schedule.selection_cost` of a presentation (Selective Backprop's; InfoBatch's scores come from its "
        "training passes); InfoBatch and Selective Backprop are stopped at the selective budget "
        f"(`schedule.budget`). The partner `{design.partner}` is conventional training scheduled for that budget (its "
        "cosine learning rate reaches zero at its own end), not a prefix of the longer conventional run. "
        f"Δ = method − {design.partner}, paired by seed; Δ < 0: the method has the lower error. Margin m = "
        f"{options.margin.describe('the method')}. Readings: *better/worse* when the Holm-adjusted paired "
        "t-test rejects Δ = 0, *equivalent within ±m* when the Holm-adjusted TOST rejects |Δ| ≥ m, else *no "
        "detectable difference*; the family is every comparison of one metric in this table."
    )


def plot_error_cost(rows: list[dict], path: Path, design: Design = DESIGN) -> None:
    """Final held-out RMS (Nm) with 95 % intervals against total cost: one panel per (regime, arm), the legend
    outside the panels. A method keeps its colour whichever others ran (the design's listed methods hold theirs);
    the methods other than the reference are drawn side by side within ±DODGE of their cost."""
    from matplotlib.ticker import FuncFormatter

    from selpres.report.sections.plots import family_styles, pyplot, save_png

    plt = pyplot()
    panels = sorted({(r["regime"], r["arm"]) for r in rows}, key=lambda k: (not k[0].startswith("paper"), k))
    regimes = sorted({p[0] for p in panels}, key=lambda g: (not g.startswith("paper"), g))
    arms = sorted({p[1] for p in panels})
    fig, axes = plt.subplots(
        len(regimes),
        len(arms),
        figsize=(4.6 * len(arms) + 2.6, 3.6 * len(regimes)),
        squeeze=False,
        layout="constrained",
    )
    methods = design.methods({*design.order, *(r["method"] for r in rows)})
    styles = family_styles(methods)
    side = [m for m in methods if m != design.reference]
    step = 2 * DODGE / max(len(side) - 1, 1)
    for i, regime in enumerate(regimes):
        for j, arm in enumerate(arms):
            ax = axes[i][j]
            for r in rows:
                if (r["regime"], r["arm"]) != (regime, arm) or r["rms_mean"] is None:
                    continue
                colour, marker = styles[r["method"]]
                lo, hi = r["rms_lo"], r["rms_hi"]
                yerr = None if lo is None else [[r["rms_mean"] - lo], [hi - r["rms_mean"]]]
                k = side.index(r["method"]) if r["method"] in side else None  # the reference at its own cost
                dodge = 1.0 if k is None else 1 + step * (k - (len(side) - 1) / 2)
                ax.errorbar(
                    r["cost"] * dodge,
                    r["rms_mean"],
                    yerr=yerr,
                    fmt=marker,
                    color=colour,
                    capsize=4,
                    ms=7,
                    label=r["method"],
                )
            ax.set_title(f"{arm}\n{regime}", fontsize=9)
            ax.set_xlabel("total cost (presentations)")
            ax.set_ylabel("final held-out RMS (Nm), mean [95 %]")
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:,.0f}"))
            ax.tick_params(axis="x", labelrotation=20)
            ax.grid(alpha=0.3)
    handles = {}
    for ax in axes.flat:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    fig.legend(list(handles.values()), list(handles), loc="outside right center", title="method")
    save_png(fig, path)


def section(ctx: Context, design: Design = DESIGN) -> Section | None:
    if not applies(ctx):
        return None
    cs = cells(ctx, design)
    summary = summary_rows(cs, design)
    verdicts = verdict_rows(cs, ctx.options, design)
    return Section(
        "Modern training and data pruning: error against total cost",
        [
            headline(verdicts),
            summary_markdown(summary),
            verdict_markdown(verdicts),
            note(ctx.options, design),
            "![final held-out RMS against total cost, per regime and arm](modern_error_cost.png)\n\n"
            "Each point: the mean over the paired seeds with its 95 % t-interval; methods of one cost are drawn "
            "side by side (within ±7 % of their cost; conventional training at its own) so their intervals "
            "can be told apart.",
        ],
        csv={"modern.csv": summary, "modern_verdict.csv": verdicts},
        figures={"modern_error_cost.png": ("error against cost", lambda p: plot_error_cost(summary, p, design))},
    )


SECTION = section
