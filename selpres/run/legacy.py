"""results.json files written by older selpres, read as today's: the one place where a finished job's record from
before a node existed is rebuilt into that node, so every reader (the report, the sweep's partners) reads one shape
and none tests a method's kind. Light on purpose (no torch): the report's command line imports it."""

from __future__ import annotations


def selector_and_cost(res: dict) -> tuple[dict, dict]:
    """A finished job's ``selector`` and ``cost`` nodes (what chose its epochs; what its ledger measured).

    The documented fallback for files written before the selector protocol (no ``cost`` node), and the only read of
    their ``pruning`` node: a job configured with ``schedule.pruning`` recorded its policy, parameters and per-replica
    cost there; a job without one was staged, every replica costing its presentations done. Files written since
    carry ``selector`` and ``cost`` for every method alike and no ``pruning`` node."""
    if "cost" in res:
        return res.get("selector") or {}, res["cost"]
    R = len(res.get("seeds") or [])
    old = res.get("pruning")
    if not old:
        spent = res["schedule"]["presentations"] + (res.get("selection_presentations") or 0)
        return {"name": "staged"}, {"presentations": spent, "per_replica": {"spent": [spent] * R}}
    per = {
        "spent": old["cost"],
        "trained": old.get("trained_presentations"),
        "charged": old.get("charged_presentations"),
        "left_out": old.get("left_out"),
        "epochs": old.get("epochs"),
    }
    cost = {
        "presentations": sum(old["cost"]) / len(old["cost"]),
        "budget": old.get("budget"),
        "selection_cost": old.get("selection_cost"),
        "per_replica": per,
    }
    ledger = {"cost", "trained_presentations", "charged_presentations", "left_out", "epochs", *cost}
    params = {k: v for k, v in old.items() if k not in ledger | {"kind", "policy"}}
    return {"name": old["kind"], "class": old.get("policy"), **params}, cost
