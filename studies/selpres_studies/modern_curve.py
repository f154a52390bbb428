"""The learning curves that size the modern study (issue 28, experiment=modern_curve): conventional training of
each arm and regime at doubling budgets, on the validation draw, and the budget where doubling it changes the final
held-out RMS by less than ``TOLERANCE`` (the study's N), else the largest run, said plainly.

The rule reads the *median* over the seeds, not the mean: with Adam + ReLU one or two of twelve seeds stall near
the error of predicting the mean at every budget (more budget does not cure it), and the mean then
moves with how many stalled rather than with the budget. The table shows both.

A job is one budget (its epochs N); the arm and regime are read as the modern study reads them
(:func:`selpres_studies.modern.arm_of`, :func:`~selpres_studies.modern.regime_of`).
"""

from __future__ import annotations

import math

from selpres.report import Context, Section, median, presents_all, summarize, table
from selpres_studies._modern_cells import DESIGN, arm_of, job_work, regime_of

TOLERANCE = 0.10  # "converged": doubling the budget changes the mean final held-out RMS by less than this share


def budgets(ctx: Context) -> dict[tuple[str, str], dict[int, dict]]:
    """(arm, regime) -> epochs N -> {cost, wall, rms: {seed: final held-out RMS}, lr} of the one-stage jobs."""
    out: dict = {}
    for job in ctx.jobs:
        res = job.results
        if job.status not in ("complete", "diverged") or not res or not presents_all(res):
            continue
        epochs = res["schedule"].get("epochs") or []
        if len(epochs) != 1 or res["schedule"].get("name") != DESIGN.reference:
            continue
        cfg = res["config"]
        if not isinstance(cfg.get("robot"), dict) or not isinstance(cfg.get("optim"), dict):
            continue  # results older than the open robot and optim nodes: not this study's
        key = (arm_of(cfg), regime_of(cfg))
        point = out.setdefault(key, {}).setdefault(epochs[0], {"rms": {}, "cost": None, "wall": [], "lr": set()})
        point["cost"] = res["schedule"]["presentations"]
        point["lr"].add(cfg["optim"]["lr"])
        if job_work(res) is not None:
            point["wall"].append(job_work(res))
        for rep in job.replicas:
            v = rep["final"]["heldout"]["nm"]["overall"] if rep["final"] else None
            if v is not None and math.isfinite(v):
                point["rms"][rep["seed"]] = v
    return out


def applies(found: dict) -> bool:
    """The sweep (its :func:`budgets`) is a learning curve: for some arm and regime, one-stage conventional training
    at three or more budgets each double the one before (N, 2N, 4N, ...)."""
    return any(_doublings(sorted(b)) >= 3 for b in found.values())


def _doublings(Ns: list[int]) -> int:
    """The longest run of budgets each twice the one before."""
    best = run = 1 if Ns else 0
    for a, b in zip(Ns, Ns[1:]):
        run = run + 1 if b == 2 * a else 1
        best = max(best, run)
    return best


def curve_rows(found: dict) -> list[dict]:
    """One row per (arm, regime, N): the mean final held-out RMS, its change at the next doubling, and whether N is
    the chosen budget (the smallest whose doubling changes it by less than TOLERANCE)."""
    rows = []
    for (arm, regime), points in sorted(found.items(), key=lambda kv: (kv[0][0], not kv[0][1].startswith("paper"))):
        Ns = sorted(points)
        means = {N: summarize(points[N]["rms"].values()) for N in Ns}
        medians = {N: median(points[N]["rms"].values()) for N in Ns}
        chosen = None
        for N, nxt in zip(Ns, Ns[1:]):
            change = (medians[nxt] - medians[N]) / medians[N]
            if nxt == 2 * N and abs(change) < TOLERANCE and chosen is None:
                chosen = N
        for i, N in enumerate(Ns):
            nxt = Ns[i + 1] if i + 1 < len(Ns) else None
            m = means[N]
            change = (medians[nxt] - medians[N]) / medians[N] if nxt is not None and medians[N] else None
            rows.append(
                {
                    "arm": arm,
                    "regime": regime,
                    "epochs": N,
                    "presentations": points[N]["cost"],
                    "lr": ",".join(f"{v:g}" for v in sorted(points[N]["lr"])),
                    "wall_s": sum(points[N]["wall"]) / len(points[N]["wall"]) if points[N]["wall"] else None,
                    "seeds": m["n"],
                    "rms_mean": m["mean"],
                    "rms_lo": m["ci95"][0],
                    "rms_hi": m["ci95"][1],
                    "rms_median": medians[N],
                    "change_at_doubling": change,
                    "chosen": N == chosen,
                    "largest": nxt is None and chosen is None,
                }
            )
    return rows


def markdown(rows: list[dict]) -> str:
    def iv(r):
        lo = "" if r["rms_lo"] is None else f" [{r['rms_lo']:.3f}, {r['rms_hi']:.3f}]"
        return f"{r['rms_mean']:.3f}{lo}"

    body = [
        [
            r["arm"],
            r["regime"],
            r["lr"],
            str(r["epochs"]),
            f"{r['presentations']:,}",
            "–" if r["wall_s"] is None else f"{r['wall_s']:.1f}",
            iv(r),
            f"{r['rms_median']:.3f}",
            "–" if r["change_at_doubling"] is None else f"{r['change_at_doubling'] * 100:+.1f} %",
            "**chosen**" if r["chosen"] else ("largest run: not converged by this rule" if r["largest"] else ""),
        ]
        for r in rows
    ]
    head = ["arm", "regime", "lr", "epochs N", "presentations", "wall s", "held-out RMS, Nm: mean [95 %]",
            "median", "median's change at 2N", "budget"]  # fmt: skip
    return table(head, body)


def section(ctx: Context) -> Section | None:
    found = budgets(ctx)
    if not applies(found):
        return None
    rows = curve_rows(found)
    return Section(
        "Learning curves: the budget where conventional training has converged",
        [
            markdown(rows),
            f"Conventional training at doubling budgets, each its own run (a cosine rate decays over its own "
            f"budget), final held-out RMS over the paired seeds on this sweep's draw. *Chosen*: the smallest N "
            f"whose doubling changes the median over the seeds by less than {TOLERANCE * 100:g} % (the median: "
            "a seed that stalls near the mean's error moves the mean whatever the budget); where no doubling "
            "does, the largest run is marked instead. Wall: the method's own seconds per job (all seeds at once).",
        ],
        csv={"modern_curve.csv": rows},
    )


SECTION = section
