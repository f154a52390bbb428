"""The learning curves that size the modern study (issues 28, 40, experiment=modern_curve): conventional training of
each arm and regime at doubling budgets, on the validation draw, and the budget where doubling it changes the median
final held-out RMS by less than ``TOLERANCE`` and does not lower the stall rate detectably (McNemar's exact test
paired by seed: the study's N), else the largest run, said plainly; beside it the share of seeds that stalled
(:func:`selpres.run.stalls.is_stalled` at the study's ``stall_share``). And the rate check (experiment=modern_lr):
conventional training of one budget at several rates, the rate with the lowest median.

The rule reads the *median* over the seeds, not the mean: with Adam + ReLU some seeds stall near the error of
predicting the mean, and the mean then moves with how many stalled rather than with the budget. The table shows
both, and the stall rate.

A job is one budget (its epochs N) at one rate; the arm and regime are read as the modern study reads them
(:func:`selpres_studies.modern.arm_of`, :func:`~selpres_studies.modern.regime_of`), the rate apart: a curve is one
(arm, regime, rate).
"""

from __future__ import annotations

import math

from selpres.report import (
    Context,
    Section,
    clopper_pearson,
    is_stalled,
    mcnemar_exact,
    median,
    presents_all,
    summarize,
    table,
)
from selpres_studies._modern_cells import DESIGN, arm_of, job_work, regime_of

TOLERANCE = 0.10  # "converged": doubling the budget changes the median final held-out RMS by less than this share
ALPHA = 0.05  # ... and does not lower the share of seeds that stalled detectably (issue 40): McNemar's exact test


def settled(point: dict, doubled: dict) -> bool:
    """Doubling the budget from ``point`` to ``doubled`` moves the median final held-out RMS by less than TOLERANCE
    and does not lower the stall rate detectably: the seeds (the same in both runs) that stalled at N but not at
    2N are not more than chance allows against those that stalled at 2N only (McNemar's exact test, p >= ALPHA).
    A seed that more budget brings out of a stall was still training, not stalled."""
    a, b = median(point["rms"].values()), median(doubled["rms"].values())
    if a is None or b is None or not abs(b - a) < TOLERANCE * a:
        return False
    t = stall_test(point, doubled)
    return t is None or t["a_only"] <= t["b_only"] or t["p"] >= ALPHA


def stall_test(point: dict, doubled: dict) -> dict | None:
    """McNemar's exact test of the stalls at N (a) against 2N (b), paired by seed, or None without stall flags."""
    sa, sb = point.get("stalled") or {}, doubled.get("stalled") or {}
    seeds = sorted(set(sa) & set(sb))
    return mcnemar_exact([sa[s] for s in seeds], [sb[s] for s in seeds]) if seeds else None


def budgets(ctx: Context) -> dict[tuple[str, str, float], dict[int, dict]]:
    """(arm, regime, lr) -> epochs N -> {cost, wall, rms: {seed: final held-out RMS}, stalled: {seed: bool}, lr} of
    the one-stage jobs."""
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
        key = (arm_of(cfg), regime_of(cfg), float(cfg["optim"]["lr"]))
        empty = {"rms": {}, "stalled": {}, "cost": None, "wall": [], "lr": set()}
        point = out.setdefault(key, {}).setdefault(epochs[0], empty)
        floor = ((res.get("floor") or {}).get("heldout") or {}).get("nm", {}).get("overall")
        point["cost"] = res["schedule"]["presentations"]
        point["lr"].add(cfg["optim"]["lr"])
        if job_work(res) is not None:
            point["wall"].append(job_work(res))
        for rep in job.replicas:
            v = rep["final"]["heldout"]["nm"]["overall"] if rep["final"] else None
            if v is not None and math.isfinite(v):
                point["rms"][rep["seed"]] = v
            if is_stalled(v, floor, DESIGN.stall_share) is not None:
                point["stalled"][rep["seed"]] = is_stalled(v, floor, DESIGN.stall_share)
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
    the chosen budget (the smallest whose doubling :func:`settled`)."""
    rows = []
    for key, points in sorted(found.items(), key=lambda kv: (kv[0][0], not kv[0][1].startswith("paper"), kv[0][2:])):
        arm, regime = key[:2]
        Ns = sorted(points)
        means = {N: summarize(points[N]["rms"].values()) for N in Ns}
        medians = {N: median(points[N]["rms"].values()) for N in Ns}
        chosen = None
        for N, nxt in zip(Ns, Ns[1:]):
            if nxt == 2 * N and chosen is None and settled(points[N], points[nxt]):
                chosen = N
        for i, N in enumerate(Ns):
            nxt = Ns[i + 1] if i + 1 < len(Ns) else None
            m = means[N]
            change = (medians[nxt] - medians[N]) / medians[N] if nxt is not None and medians[N] else None
            stalled = points[N].get("stalled") or {}
            t = stall_test(points[N], points[nxt]) if nxt == 2 * N else None
            rows.append(
                {
                    "arm": arm,
                    "regime": regime,
                    "epochs": N,
                    "presentations": points[N]["cost"],
                    "lr": f"{key[2]:g}" if len(key) > 2 else ",".join(f"{v:g}" for v in sorted(points[N]["lr"])),
                    "wall_s": sum(points[N]["wall"]) / len(points[N]["wall"]) if points[N]["wall"] else None,
                    "seeds": m["n"],
                    "rms_mean": m["mean"],
                    "rms_lo": m["ci95"][0],
                    "rms_hi": m["ci95"][1],
                    "rms_median": medians[N],
                    "stalls": sum(stalled.values()),
                    "stall_seeds": len(stalled),
                    "change_at_doubling": change,
                    "stalled_only_here": None if t is None else t["a_only"],
                    "stalled_only_at_2n": None if t is None else t["b_only"],
                    "stall_p_at_2n": None if t is None else t["p"],
                    "chosen": N == chosen,
                    "largest": nxt is None and chosen is None,
                }
            )
    return rows


def _stalled(r: dict) -> str:
    if not r.get("stall_seeds"):
        return "–"
    lo, hi = clopper_pearson(r["stalls"], r["stall_seeds"])
    return f"{r['stalls']}/{r['stall_seeds']} [{lo * 100:.0f}, {hi * 100:.0f} %]"


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
            _stalled(r),
            "–" if r["change_at_doubling"] is None else f"{r['change_at_doubling'] * 100:+.1f} %",
            "–"
            if r.get("stall_p_at_2n") is None
            else f"{r['stalled_only_here']} / {r['stalled_only_at_2n']} (p = {r['stall_p_at_2n']:.2g})",
            "**chosen**" if r["chosen"] else ("largest run: not converged by this rule" if r["largest"] else ""),
        ]
        for r in rows
    ]
    head = ["arm", "regime", "lr", "epochs N", "presentations", "wall s", "held-out RMS, Nm: mean [95 %]",
            "median", "stalled [exact 95 %]", "median's change at 2N", "seeds stalled only at N / only at 2N",
            "budget"]  # fmt: skip
    return table(head, body)


def rate_rows(found: dict) -> list[dict]:
    """The rate check (experiment=modern_lr): per (arm, regime, N) run at two or more rates, one row per rate with
    its median final held-out RMS and stall rate; *chosen*: the lowest median."""
    at: dict = {}
    for key, points in found.items():
        for N, p in points.items():
            at.setdefault((*key[:2], N), {})[key[2] if len(key) > 2 else None] = p
    rows = []
    for (arm, regime, N), by_lr in sorted(at.items(), key=lambda kv: (kv[0][0], not kv[0][1].startswith("paper"))):
        if len(by_lr) < 2:
            continue
        medians = {lr: median(p["rms"].values()) for lr, p in by_lr.items()}
        best = min((m, lr) for lr, m in medians.items() if m is not None)[1]
        for lr in sorted(by_lr):
            stalled = by_lr[lr].get("stalled") or {}
            rows.append(
                {
                    "arm": arm,
                    "regime": regime,
                    "epochs": N,
                    "lr": lr,
                    "seeds": len(by_lr[lr]["rms"]),
                    "rms_median": medians[lr],
                    "rms_mean": summarize(by_lr[lr]["rms"].values())["mean"],
                    "stalls": sum(stalled.values()),
                    "stall_seeds": len(stalled),
                    "chosen": lr == best,
                }
            )
    return rows


def rate_markdown(rows: list[dict]) -> str:
    body = [
        [
            r["arm"],
            r["regime"],
            str(r["epochs"]),
            f"{r['lr']:g}",
            f"{r['rms_median']:.3f}",
            f"{r['rms_mean']:.3f}",
            _stalled(r),
            "**chosen**" if r["chosen"] else "",
        ]  # fmt: skip
        for r in rows
    ]
    head = ["arm", "regime", "epochs N", "lr", "median held-out RMS, Nm", "mean", "stalled [exact 95 %]", "rate"]
    return table(head, body)


def section(ctx: Context) -> Section | None:
    found = budgets(ctx)
    rates = rate_rows(found)
    if not applies(found) and not rates:
        return None
    blocks, csv = [], {}
    if applies(found):
        rows = curve_rows(found)
        csv["modern_curve.csv"] = rows
        blocks += [
            markdown(rows),
            f"Conventional training at doubling budgets, each its own run (a cosine rate decays over its own "
            f"budget), final held-out RMS over the paired seeds on this sweep's draw. *Chosen*: the smallest N "
            f"whose doubling changes the median over the seeds by less than {TOLERANCE * 100:g} % (the median: "
            "a seed that stalls near the mean's error moves the mean whatever the budget) and does not lower the "
            "stall rate detectably (McNemar's exact test on the seeds that stalled at one budget only, p ≥ "
            f"{ALPHA:g}: a seed more budget brings out of a stall was still training); where no doubling does, the "
            "largest run is marked instead. *Stalled*: final held-out "
            "RMS at least "
            f"{DESIGN.stall_share * 100:g} % of predicting the training mean's (Clopper–Pearson interval). Wall: the "
            "method's own seconds per job (all seeds at once).",
        ]
    if rates:
        csv["modern_rates.csv"] = rates
        blocks += [
            rate_markdown(rates),
            "The rate at a budget: conventional training at that N at each rate run, on this sweep's draw; "
            "*chosen*: the lowest median final held-out RMS.",
        ]
    return Section("Learning curves: the budget where conventional training has converged", blocks, csv=csv)


SECTION = section
