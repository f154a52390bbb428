"""Table 1 in the paper's layout: attributes down the side, one column per (method, topology), with the
paper's numbers beside ours."""

from __future__ import annotations

from selpres.report.context import Context, Section
from selpres.report.groups import SETS, UNITS, Group
from selpres.report.markdown import ci, engine_text, fmt, mean_std, table
from selpres.report.paper import PAPER, paper_setting
from selpres.run.stats import summarize

FOOTNOTE = (
    "¹ The paper's RMS error is over 10 test patterns with units unstated; it is shown next to both of our "
    "metrics (Nm and scaled). Ours: mean ± sample std over complete seeds, and the Student-t 95 % interval "
    "of the mean. *test-10* = the paper's 10-pattern metric, *held-out* = all held-out patterns. Wall time "
    "per replica-run = the job's training seconds ÷ its replicas (replicas are trained together, batched), "
    "measured with the engine named after it (and the one requested, when the run fell back). "
    "Diverged replicas (and any whose final score is not finite) are excluded from means and counted under "
    "*replicas complete*.\n\n"
    "² nMSE = held-out MSE ÷ the variance of the held-out torques, the mean over joints (the inverse-dynamics "
    "literature's metric; 1 = no better than a constant); the mean predictor's RMS is the error of always "
    "predicting the exemplar set's mean torque, the task's floor."
)


def replicas_text(g: Group) -> str:
    """complete/all, and why the others are not: diverged, or a final score that is not finite (report.validate)."""
    n, bad = len(g.by_seed), [r["status"] for r in g.by_seed.values() if r["status"] != "complete"]
    why = ", ".join(f"{bad.count(k)} {k}" for k in dict.fromkeys(bad))
    return f"{n - len(bad)}/{n}" + (f" ({why})" if bad else "")


def table1_rows(groups, topologies, methods) -> list[dict]:
    """One row per (method, topology): schedule, cost, wall time, paper RMS and our RMS statistics."""
    rows = []
    for m in methods:
        for t in topologies:
            g = groups.get((t, m))
            row = {"method": m, "topology": t}
            if g is None or g.sched is None:
                row["replicas"] = "no results"
                rows.append(row)
                continue
            s, w = g.sched, g.wall()
            row.update(
                p=s["p"],
                sizes=" ".join(map(str, s["sizes"])),
                epochs=" ".join(map(str, s["epochs"])),
                extra_presentations=sum(s.get("extra_presentations") or [0]),
                presentations=s["presentations"],
                paper_presentations=PAPER.get(m, {}).get("presentations"),
                cost_ratio_vs_equal_epochs=s["cost_ratio"],
                paper_setting=paper_setting(g.schedule, s),
                replicas=replicas_text(g),
                n_complete=len(g.complete_seeds),
                n_diverged=g.n_diverged,
                **g.engines(),
                wall_train_per_replica_s=w["per_replica"],
                wall_train_job_s=w["train"],
                wall_total_job_s=w["total"],
                paper_rms=PAPER.get(m, {}).get("rms", {}).get(t),
            )
            for set_, _ in SETS:
                for unit, _ in UNITS:
                    st = summarize(g.values(set_, unit).values())
                    k = f"{set_}_{unit}"
                    row.update(
                        {
                            f"{k}_n": st["n"],
                            f"{k}_mean": st["mean"],
                            f"{k}_std": st["std"],
                            f"{k}_ci_lo": st["ci95"][0],
                            f"{k}_ci_hi": st["ci95"][1],
                        }
                    )
            st = summarize(g.values("heldout", "nmse").values())  # selpres.run.floor: MSE ÷ target variance
            floor = (g.used[0].results.get("floor") or {}).get("heldout", {}).get("nm", {}).get("overall")
            row.update(heldout_nmse_mean=st["mean"], heldout_nmse_std=st["std"], heldout_floor_nm=floor)
            rows.append(row)
    return rows


def stat_of(row: dict, k: str) -> dict:
    """The summarize()-shaped statistics of column group ``k`` (e.g. "heldout_nm") of a Table 1 row."""
    return {
        "mean": row.get(f"{k}_mean"),
        "std": row.get(f"{k}_std"),
        "ci95": [row.get(f"{k}_ci_lo"), row.get(f"{k}_ci_hi")],
    }


def _paper_time(r: dict) -> str:
    paper = PAPER.get(r["method"])
    if not paper:
        return "not in paper"
    return f"{paper['presentations']:,}t" + (f" (printed {paper['printed']})" if r["method"] == "conventional" else "")


def _epochs(r: dict) -> str:
    return r["epochs"] + (f" (+{r['extra_presentations']} presentations)" if r["extra_presentations"] else "")


def _wall(r: dict) -> str:
    job = f"{r['wall_train_job_s']:.3g} / {r['wall_total_job_s']:.3g}"
    return f"{r['wall_train_per_replica_s']:.3g} ({job}) {engine_text(r)}"


def _rms_cells() -> list[tuple]:
    """(label, cell) for our RMS rows: each set and unit, mean ± std then the 95 % interval."""
    return [
        (f"{sname} RMS {uname}, {what}", lambda r, k=f"{set_}_{unit}", show=show: show(stat_of(r, k)))
        for set_, sname in SETS
        for unit, uname in UNITS
        for what, show in (("mean ± std", mean_std), ("95 % CI", ci))
    ]


def _cells() -> list[tuple]:
    """(label, cell(row) -> text) for every line of the table, top to bottom."""
    return [
        ("p", lambda r: str(r["p"]) if r["p"] else "-"),
        ("size of the set n_i", lambda r: r["sizes"]),
        ("no. of epochs N_i", _epochs),
        ("total time T (ours)", lambda r: f"{r['presentations']:,}t"),
        ("total time T (paper)", _paper_time),
        ("paper's n_i, N_i (or budget)?", lambda r: r["paper_setting"]),
        ("wall s per replica-run (job train / total), engine that ran", _wall),
        ("replicas complete", lambda r: r["replicas"]),
        ("rms error, paper¹", lambda r: fmt(r["paper_rms"]) if r["paper_rms"] is not None else "—"),
        *_rms_cells(),
        ("held-out nMSE², mean ± std", lambda r: mean_std(stat_of(r, "heldout_nmse"))),
        ("held-out RMS of the mean predictor² Nm", lambda r: fmt(r["heldout_floor_nm"])),
    ]


def table1_markdown(rows: list[dict]) -> str:
    """The paper's layout: attributes down the side, one column per (method, topology)."""

    def cell(r, label, show):
        if r.get("presentations") is None:  # no results for this column
            return r.get("replicas", "") if label == "replicas complete" else "—"
        return show(r)

    header = ["Table 1"] + [f"{r['method']} {r['topology']}" for r in rows]
    return table(header, [[label] + [cell(r, label, show) for r in rows] for label, show in _cells()])


def section(ctx: Context) -> Section:
    """Table 1 in the paper's layout for a Table-1-like sweep; for a study of parameters, whose methods
    would make one column each, a pointer to the same numbers in table1.csv."""
    rows = table1_rows(ctx.groups, ctx.topologies, ctx.methods)
    title = "Table 1 (paper's layout, with the paper's numbers)"
    if ctx.table1_like:
        return Section(title, [table1_markdown(rows), FOOTNOTE], csv={"table1.csv": rows})
    tops = f"{len(ctx.topologies)} topolog{'ies' if len(ctx.topologies) > 1 else 'y'}"
    note = (
        f"Not laid out: this sweep is a study of parameters, not Table 1's grid of the paper's methods "
        f"({len(ctx.methods)} methods × {tops}, labelled by the settings they sweep), so Table 1's "
        "layout would have one column each. `table1.csv` holds every column (schedule, cost, wall time, "
        "replicas, mean / std / 95 % interval of each metric); the sections above read them."
    )
    return Section(title, [note], csv={"table1.csv": rows})
