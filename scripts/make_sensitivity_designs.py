"""Writes the rivals' grid of experiment=sensitivity: selpres/configs/design/{sgd,qp,dbd,adam,rprop}_*.yaml.

Each rival optimizer is run over a Cartesian grid of its critical parameters (the ranges and their sources:
configs/experiment/sensitivity.yaml's comment) at two costs: the paper's (c150300: 150 epochs of n = 1002,
schedule=conventional) and the paper's selective schedule's (c70560: schedule=matched). Edit a range here and
run it again (``python scripts/make_sensitivity_designs.py``); the experiment sweeps the files by glob, so no
list of names is kept anywhere else, and tests/test_sensitivity.py regenerates them and finds no difference.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "selpres" / "configs" / "design"
COSTS = {  # cost -> (schedule, what it is)
    150_300: ("conventional", "At the paper's cost: 150 epochs of all n = 1002 (schedule=conventional)."),
    70_560: ("matched", "At the selective cost: the paper's selective budget (schedule=matched)."),
}
# prefix -> (optim group file, the rule as the first line says it, [(config key, its name in the file name, values)])
RIVALS = {
    "sgd": (
        "paper",
        "Online SGD + momentum (Rumelhart et al.)",
        [("lr", "lr", ("0.05", "0.15", "0.5")), ("momentum", "m", ("0", "0.5", "0.9"))],
    ),
    "qp": (
        "quickprop",
        "QuickProp (Fahlman 1988), batch mode",
        [("lr", "eps", ("0.0003", "0.001", "0.003")), ("mu", "mu", ("1.25", "1.75", "2.25"))],
    ),
    "dbd": (
        "delta_bar_delta",
        "Delta-Bar-Delta (Jacobs 1988), batch mode, initial rate lr 0.001",
        [
            ("kappa", "k", ("0.001", "0.003", "0.01")),
            ("phi", "phi", ("0.2", "0.5", "0.8")),
            ("theta", "th", ("0.5", "0.7", "0.9")),
        ],
    ),
    "adam": (
        "adam",
        "Adam (Kingma & Ba 2015), batch mode",
        [("lr", "lr", ("0.001", "0.003", "0.01", "0.03", "0.1", "0.3"))],
    ),
    "rprop": (
        "rprop",
        "Rprop (Riedmiller & Braun 1993), batch mode",
        [("lr", "lr", ("0.01", "0.1", "1")), ("eta_plus", "etap", ("1.1", "1.2", "1.5"))],
    ),
}
PAPER_SGD = {  # the paper's own setting (Note 1 of Table 1) at each cost
    150_300: "The paper's settings: Table 1's conventional run.",
    70_560: "The paper's settings: the budget-matched partner of sel_paper (Table 1's matched run).",
}


def designs() -> dict[str, str]:
    """file name -> contents, for every rival, setting and cost."""
    out = {}
    for prefix, (group, rule, params) in RIVALS.items():
        for cost, (schedule, where) in COSTS.items():
            for values in itertools.product(*(vals for _, _, vals in params)):
                tag = "_".join(f"{short}{v}" for (_, short, _), v in zip(params, values))
                said = ", ".join(f"{key} {v}" for (key, _, _), v in zip(params, values))
                lines = ["# @package _global_", f"# {rule}: {said}.", f"# {where}"]
                if prefix == "sgd" and values == ("0.15", "0.9"):
                    lines.append(f"# {PAPER_SGD[cost]}")
                lines += [f"# cost: {cost:,} presentations", "defaults:", f"  - override /schedule: {schedule}"]
                lines += [f"  - override /optim: {group}", "optim:"]
                lines += [f"  {key}: {v}" for (key, _, _), v in zip(params, values)]
                out[f"{prefix}_c{cost}_{tag}.yaml"] = "\n".join(lines) + "\n"
    return out


def main(out: Path = OUT) -> None:
    out.mkdir(parents=True, exist_ok=True)
    files = designs()
    stale = [p.name for p in out.glob("*.yaml") if p.name.split("_")[0] in RIVALS and p.name not in files]
    for name in stale:  # a setting taken out of a range above
        (out / name).unlink()
    for name, text in files.items():
        (out / name).write_text(text)
    print(f"wrote {len(files)} files into {out}" + (f", removed {len(stale)}" if stale else ""))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
