"""Stalls as their own outcome in the modern study (:mod:`selpres_studies.modern`, issue 40).

Per arm, regime and method: how many seeds stalled (a final held-out RMS at least ``design.stall_share`` of the
mean predictor's, :func:`selpres.run.stalls.is_stalled`) with the exact Clopper–Pearson interval of the rate, and
McNemar's exact test, paired by seed, of whether the method stalls more or less often than the reference; the
evidence of the cause beside it, the hidden units that ended dead or linear (results.json ``stalls``). Holm's
correction runs over the sweep's stall tests (a family of its own: a different outcome from the error's).

The remedy (a regime that differs from another only in its hidden units, ``design.remedies``) is compared with it
the same way, method by method, paired by seed: the same seeds start from the same weights and see the same
shuffles, so a discordant pair is one seed the remedy moved.
"""

from __future__ import annotations

from selpres.report import clopper_pearson, holm, mcnemar_exact, median, table
from selpres_studies._modern_cells import DESIGN, Cell, Design, _arm_regimes


def _units(c: Cell, stalled: bool) -> dict:
    """Median dead and linear hidden units of the cell's seeds that did (``stalled``) or did not stall."""
    seeds = [s for s, v in c.stalled.items() if v is stalled and s in c.dead]
    return {
        "runs": len(seeds),
        "dead": median(c.dead[s] for s in seeds),
        "linear": median(c.linear[s] for s in seeds),
    }


def _rate(c: Cell) -> dict:
    k, n = sum(c.stalled.values()), len(c.stalled)
    lo, hi = clopper_pearson(k, n)
    return {"stalls": k, "seeds": n, "rate": k / n if n else None, "rate_lo": lo, "rate_hi": hi}


def _mcnemar(c: Cell, other: Cell) -> dict:
    seeds = sorted(set(c.stalled) & set(other.stalled))
    t = mcnemar_exact([c.stalled[s] for s in seeds], [other.stalled[s] for s in seeds])
    return {"pairs": t["n"], "only_this": t["a_only"], "only_other": t["b_only"], "p": t["p"]}


def stall_rows(cs: dict, design: Design = DESIGN) -> list[dict]:
    """One row per (arm, regime, method): the stall rate with its exact interval, the dead and linear units of the
    stalled and the other runs, and (every method but the reference) McNemar's exact test against the reference,
    Holm-adjusted over every such test of the sweep (``p_holm``)."""
    rows = []
    methods = design.methods(m for _, _, m in cs)
    for arm, regime in _arm_regimes(cs, design):
        ref = cs.get((arm, regime, design.reference))
        for method in methods:
            c = cs.get((arm, regime, method))
            if c is None or not c.stalled:
                continue
            row = {"arm": arm, "regime": regime, "method": method, **_rate(c), "hidden": c.hidden}
            for flag, name in ((True, "stalled"), (False, "other")):
                row.update({f"{name}_{k}": v for k, v in _units(c, flag).items()})
            if ref is not None and method != design.reference and ref.stalled:
                row.update({f"vs_ref_{k}": v for k, v in _mcnemar(c, ref).items()})
            rows.append(row)
    _holm(rows, "vs_ref")
    return rows


def _holm(rows: list[dict], prefix: str) -> None:
    tested = [r for r in rows if r.get(f"{prefix}_p") is not None]
    for r, p in zip(tested, holm([r[f"{prefix}_p"] for r in tested])):
        r[f"{prefix}_p_holm"] = p


def remedy_rows(cs: dict, design: Design = DESIGN) -> list[dict]:
    """Per arm and method, each remedy regime against the regime it remedies (``design.remedies``: the remedy's
    hidden units -> the units it replaces, both as the regime's label shows them): both stall rates and McNemar's
    exact test paired by seed, Holm-adjusted over these tests."""
    rows = []
    for arm, regime in _arm_regimes(cs, design):
        for units, base_units in design.remedies.items():
            shown, base_shown = design.activations.get(units, units), design.activations.get(base_units, base_units)
            if not regime.endswith(f", {shown}"):
                continue
            base = regime[: -len(shown)] + base_shown
            for method in design.methods(m for _, _, m in cs):
                c, b = cs.get((arm, regime, method)), cs.get((arm, base, method))
                if c is None or b is None or not c.stalled or not b.stalled:
                    continue
                row = {"arm": arm, "regime": regime, "remedies": base, "method": method}
                row.update({f"base_{k}": v for k, v in _rate(b).items()})
                row.update({f"remedy_{k}": v for k, v in _rate(c).items()})
                row.update({f"base_{k}": v for k, v in _units(b, True).items()})
                row.update({f"vs_base_{k}": v for k, v in _mcnemar(c, b).items()})
                rows.append(row)
    _holm(rows, "vs_base")
    return rows


def _pct(k, n, lo, hi) -> str:
    return "–" if not n else f"{k}/{n} ({k / n * 100:.0f} % [{lo * 100:.0f}, {hi * 100:.0f}])"


def _p(v) -> str:
    return "–" if v is None else f"{v:.2g}"


def _med(v) -> str:
    return "–" if v is None else f"{v:g}"


def stall_markdown(rows: list[dict], design: Design = DESIGN) -> str:
    body = []
    for r in rows:
        tested = r.get("vs_ref_p") is not None
        body.append(
            [
                r["arm"],
                r["regime"],
                r["method"],
                _pct(r["stalls"], r["seeds"], r["rate_lo"], r["rate_hi"]),
                f"{r['vs_ref_only_this']} / {r['vs_ref_only_other']}" if tested else "–",
                f"{_p(r['vs_ref_p'])} ({_p(r['vs_ref_p_holm'])})" if tested else "(the reference)",
                f"{_med(r['stalled_dead'])} + {_med(r['stalled_linear'])}" if r["stalled_runs"] else "–",
                f"{_med(r['other_dead'])} + {_med(r['other_linear'])}" if r["other_runs"] else "–",
            ]
        )
    head = ["arm", "regime", "method", "stalled (rate [exact 95 %])",
            f"stalled only here / only in {design.reference}", "McNemar exact p (Holm)",
            "stalled runs: dead + linear units (median)", "other runs: dead + linear units (median)"]  # fmt: skip
    return table(head, body)


def remedy_markdown(rows: list[dict]) -> str:
    body = [
        [
            r["arm"],
            r["method"],
            _pct(r["base_stalls"], r["base_seeds"], r["base_rate_lo"], r["base_rate_hi"]),
            _pct(r["remedy_stalls"], r["remedy_seeds"], r["remedy_rate_lo"], r["remedy_rate_hi"]),
            f"{r['vs_base_only_this']} / {r['vs_base_only_other']}",
            f"{_p(r['vs_base_p'])} ({_p(r['vs_base_p_holm'])})",
        ]
        for r in rows
    ]
    head = ["arm", "method", "stalled without the remedy", "stalled with it", "seeds stalled only with / only without",
            "McNemar exact p (Holm)"]  # fmt: skip
    return table(head, body)
