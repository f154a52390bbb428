"""What the report reads of a finished job's ``results.json``, checked once as it is loaded, so no section meets a
value it cannot use (a hand-edited, cut or foreign file; a job that wrote NaN).

Three outcomes: a field the report reads that is missing or of the wrong type makes the job *unreadable*, listed
in the Runs section naming the field, the value and what was expected (its numbers are used nowhere); a
non-finite curve value is read as missing (as ``train`` writes a diverged replica's) and counted in the job's
notes; a replica whose final scores are not all finite numbers is *not complete* (``status`` ``not finite``),
so it is counted out of "replicas complete" and out of every mean, never averaged over the other seeds.
"""

from __future__ import annotations

import math

NUMBER = "number"  # an int or a finite float (not a bool)
# the fields the sections read with [] (the others are read with .get and a default)
FINISHED = {
    "schedule": {
        "name": str,
        "sizes": [int],
        "epochs": [int],
        "p": int,
        "presentations": NUMBER,
        "cost_ratio": NUMBER,
        "presentations_per_stage": [NUMBER],
    },
    "topology": str,
    "replicas": int,
    "summary": dict,
    "wall_seconds": {"total": NUMBER, "train": NUMBER},
    "replica_results": [{"seed": int, "status": str}],
    "curves": [{"epoch": int, "presentations": NUMBER}],
}
CURVES = ("heldout_rms_nm", "test10_rms_nm", "train_mse")  # per-replica lists of a curve record (or null)
FINAL_SETS, FINAL_UNITS = ("test10", "heldout"), ("nm", "scaled")
SHOWN = 3  # problems named in the one line; the rest counted


def _what(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # nan, inf
    text = repr(value)
    return f"a {type(value).__name__} {text[:40]}" if isinstance(value, str | list | dict) else text


def _expected(spec) -> str:
    if spec == NUMBER:
        return "a finite number"
    if isinstance(spec, dict):
        return "an object"
    if isinstance(spec, list):
        return f"a list of {_expected(spec[0]).removeprefix('a ').removeprefix('an ')}s"
    return {str: "a string", int: "an integer", dict: "an object", list: "a list"}[spec]


def _fits(value, spec) -> bool:
    if spec == NUMBER:
        return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if spec is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if isinstance(spec, dict):
        return isinstance(value, dict)
    if isinstance(spec, list):
        return isinstance(value, list)
    return isinstance(value, spec)


def _check(value, spec, path: str, problems: list[str]) -> None:
    if not _fits(value, spec):
        problems.append(f"{path} is {_what(value)} ({_expected(spec)} expected)")
    elif isinstance(spec, dict):
        for key, sub in spec.items():
            if key not in value:
                problems.append(f"{path}.{key} is missing ({_expected(sub)} expected)".lstrip("."))
            else:
                _check(value[key], sub, f"{path}.{key}".lstrip("."), problems)
    elif isinstance(spec, list):
        for i, item in enumerate(value):
            _check(item, spec[0], f"{path}[{i}]", problems)


def problems_of(res: dict) -> list[str]:
    """Why a finished job's results cannot be read by the report (empty: they can); the curve lists included."""
    problems: list[str] = []
    _check(res, FINISHED, "", problems)
    if problems:
        return problems
    replicas = len(res["replica_results"])
    for i, rec in enumerate(res["curves"]):
        for key in CURVES:
            v = rec.get(key)
            if v is None:
                continue
            if not isinstance(v, list) or len(v) != replicas:
                problems.append(f"curves[{i}].{key} is {_what(v)} (null or a list of {replicas} numbers expected)")
            elif bad := [x for x in v if x is not None and not isinstance(x, int | float) or isinstance(x, bool)]:
                problems.append(f"curves[{i}].{key} holds {_what(bad[0])} (numbers or null expected)")
    return problems


def finite_curves(res: dict) -> int:
    """Non-finite curve values read as missing (null), as train writes them; returns how many there were."""
    n = 0
    for rec in res["curves"]:
        for key in CURVES:
            v = rec.get(key)
            if isinstance(v, list) and any(isinstance(x, float) and not math.isfinite(x) for x in v):
                n += sum(isinstance(x, float) and not math.isfinite(x) for x in v)
                rec[key] = [None if isinstance(x, float) and not math.isfinite(x) else x for x in v]
    return n


def _final_problem(final) -> str | None:
    """Why a complete replica's final scores are not usable (None: every one is a finite number)."""
    if not isinstance(final, dict):
        return f"its final scores are {_what(final)}"
    for s in FINAL_SETS:
        for u in FINAL_UNITS:
            scores = (final.get(s) or {}).get(u) if isinstance(final.get(s), dict) else None
            if not isinstance(scores, dict) or "overall" not in scores:
                return f"final {s}.{u} is {_what(scores)}"
            for joint, v in scores.items():
                if not _fits(v, NUMBER):
                    return f"final {s}.{u}.{joint} is {_what(v)}"
    return None


def finite_replicas(res: dict) -> list[str]:
    """Replicas reported complete whose final scores are not all finite numbers become ``not finite`` (not
    complete: out of every mean and count of complete replicas); returns a note per replica."""
    notes = []
    for rep in res["replica_results"]:
        if rep["status"] == "complete" and (why := _final_problem(rep.get("final"))):
            rep["status"], rep["not_finite"] = "not finite", why
            notes.append(f"seed {rep['seed']}: {why}")
    return notes


def describe(problems: list[str]) -> str:
    more = len(problems) - SHOWN
    return "; ".join(problems[:SHOWN]) + (f"; and {more} more" if more > 0 else "")
