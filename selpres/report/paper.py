"""The paper's Table 1, as printed, and whether one of our schedules is the paper's setting."""

from __future__ import annotations

from selpres.report.groups import base

# T_con/t = 1002·150 = 150,300 (the paper prints "1,50,000t"); its RMS units are unstated.
PAPER = {
    "conventional": {
        "p": 0,
        "sizes": [1002],
        "epochs": [150],
        "presentations": 150_300,
        "printed": "1,50,000t",
        "rms": {"6-4-2": 0.0554, "6-8-2": 0.1039, "6-13-2": 0.0872},
    },
    "selective": {
        "p": 4,
        "sizes": [50, 100, 400, 800, 1002],
        "epochs": [30] * 5,
        "presentations": 70_560,
        "printed": "70,560t",
        "rms": {"6-4-2": 0.0581, "6-8-2": 0.0659, "6-13-2": 0.0824},
    },
}
PAPER_UNITS_NOTE = "paper (units unstated)"
# Note 1 of Table 1: SGD with momentum, online; what configs/optim/paper.yaml holds (optim._target_ "sgd";
# "paper" or none in results written before the optimizer group).
PAPER_OPTIM = {"_target_": "sgd", "lr": 0.15, "momentum": 0.9, "batch_size": 1}


def _stages(sched: dict, method: str) -> bool:
    return (sched["sizes"], sched["epochs"]) == (PAPER[method]["sizes"], PAPER[method]["epochs"])


def paper_setting(method: str, sched: dict | None) -> str:
    """Whether a schedule is the paper's: "yes"/"no" for the paper's two methods; matched and random growth
    are not in the paper, so they say whose setting they borrow (selective's budget, selective's stages)."""
    if sched is None:
        return ""
    name = base(method)  # a labelled variant ("selective schedule.sizes=[…]") is still selective
    if name == "matched":
        if sched["presentations"] == PAPER["selective"]["presentations"]:
            return "not in paper (selective's budget)"
        return f"not in paper (budget {sched['presentations']:,}t, not selective's)"
    if name == "random_growth":
        if _stages(sched, "selective"):
            return "not in paper (selective's stages, random order)"
        return "not in paper (random order, other stages than selective's)"
    if name not in PAPER:
        return "n/a"
    return "yes" if _stages(sched, name) else "no"
