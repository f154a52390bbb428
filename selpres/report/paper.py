"""The paper's Table 1, as printed, and whether one of our schedules is the paper's setting."""

from __future__ import annotations

# T_con/t = 1002·150 = 150,300 (the paper prints "1,50,000t"); its RMS units are unstated.
PAPER = {
    "conventional": {
        "p": 0, "sizes": [1002], "epochs": [150], "presentations": 150_300, "printed": "1,50,000t",
        "rms": {"6-4-2": 0.0554, "6-8-2": 0.1039, "6-13-2": 0.0872},
    },
    "selective": {
        "p": 4, "sizes": [50, 100, 400, 800, 1002], "epochs": [30] * 5, "presentations": 70_560,
        "printed": "70,560t",
        "rms": {"6-4-2": 0.0581, "6-8-2": 0.0659, "6-13-2": 0.0824},
    },
}
PAPER_UNITS_NOTE = "paper (units unstated)"


def paper_setting(method: str, sched: dict | None) -> str:
    """'yes' when the schedule is the paper's (conventional, selective, random_growth's stages, matched
    budget)."""
    ref = {"random_growth": "selective"}.get(method, method)
    if sched is None:
        return ""
    if method == "matched":
        return "yes" if sched["presentations"] == PAPER["selective"]["presentations"] else "no"
    if ref not in PAPER:
        return "n/a"
    return "yes" if (sched["sizes"], sched["epochs"]) == (PAPER[ref]["sizes"], PAPER[ref]["epochs"]) else "no"
