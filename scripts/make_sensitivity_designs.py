"""Writes every design point of experiment=sensitivity into configs/design/: selective presentation one
factor at a time around the paper's schedule with its budget-matched partners ({sel,matched}_*.yaml), and the
rivals' grids ({sgd,qp,dbd,adam,rprop}_*.yaml).

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

OUT = Path(__file__).resolve().parents[1] / "configs" / "design"
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


N, N1, EPOCHS = 1002, 50, 150  # the paper's n, n1 and sum N_i
PAPER_SIZES = [50, 100, 400, 800, 1002]
# name -> (what the first line says, n_i, N_i); a second comment line where one is given
SELECTIVE = {
    "N_300": ("total epochs N = 300 (N_i = 60), the paper's n_i", PAPER_SIZES, [60] * 5),
    "N_75": ("total epochs N = 75 (N_i = 15), the paper's n_i", PAPER_SIZES, [15] * 5),
    "Ni_decreasing": ("N_i decreasing 50,40,30,20,10 (sum 150), the paper's n_i", PAPER_SIZES, [50, 40, 30, 20, 10]),
    "Ni_increasing": ("N_i increasing 10,20,30,40,50 (sum 150), the paper's n_i", PAPER_SIZES, [10, 20, 30, 40, 50]),
    "growth_linear": (
        "linear growth of n_i from n1 = 50 (equal increments), N_i = 30",
        [N1 + k * (N - N1) // 4 for k in range(5)],
        [30] * 5,
    ),
    **{
        f"n1_{n1}": (f"n1 = {n1}, the paper's other n_i and N_i", [n1, *PAPER_SIZES[1:]], [30] * 5)
        for n1 in (10, 25, 75)
    },
    "paper": (
        "the paper's schedule (Table 1): p = 4, n_i = 50,100,400,800,1002, N_i = 30",
        PAPER_SIZES,
        [30] * 5,
    ),
}
GEOMETRIC_NOTE = {4: "(also the growth factor's geometric level)."}


def geometric(p: int) -> tuple[list[int], list[int]]:
    """p + 1 stages, n_i geometric from n1 to n (rounded), N_i equal with sum N_i = 150 (the remainder last)."""
    sizes = [round(N1 * (N / N1) ** (i / p)) for i in range(p + 1)]
    base, extra = divmod(EPOCHS, p + 1)
    return sizes, [base + (i >= p + 1 - extra) for i in range(p + 1)]


def selective() -> dict[str, str]:
    """sel_<name>.yaml and, for each cost, its budget-matched partner matched_<cost>.yaml."""
    out, partners = {}, {}
    points = {
        f"p{p}": (f"p = {p}: n_i geometric from n1 = 50 to n, N_i equal with sum N_i = 150", *geometric(p))
        for p in range(1, 7)
    }
    for name, (what, sizes, epochs) in sorted({**SELECTIVE, **points}.items()):
        cost = sum(n * e for n, e in zip(sizes, epochs))
        note = GEOMETRIC_NOTE.get(len(sizes) - 1) if name in points else None
        first = f"# Selective presentation, {what}" + ("" if note else ".")
        lines = ["# @package _global_", first, *([f"# {note}"] if note else []), f"# cost: {cost:,} presentations"]
        lines += ["defaults:", "  - override /schedule: selective", "schedule:", f"  sizes: {sizes}".replace("'", "")]
        out[f"sel_{name}.yaml"] = "\n".join([*lines, f"  epochs: {epochs}", ""])
        if name != "paper":  # the paper's partner is sgd_c70560_lr0.15_m0.9 (Table 1's matched run)
            partners.setdefault(cost, []).append(f"sel_{name}")
    for cost, names in partners.items():
        out[f"matched_{cost}.yaml"] = "\n".join(
            [
                "# @package _global_",
                f"# Conventional training (online SGD, lr 0.15, momentum 0.9) stopped at {cost:,} presentations:",
                f"# the budget-matched partner of {', '.join(sorted(names, key=_partner_order))}.",
                f"# cost: {cost:,} presentations",
                "defaults:",
                "  - override /schedule: matched",
                "schedule:",
                f"  budget: {cost}",
                "",
            ]
        )
    return out


def _partner_order(name: str) -> tuple[int, str]:
    return (0 if name.startswith("sel_p") else 1, name)


def designs() -> dict[str, str]:
    """file name -> contents, for every selective point and partner, and every rival, setting and cost."""
    out = selective()
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
    ours = (*RIVALS, "sel", "matched")
    stale = [p.name for p in out.glob("*.yaml") if p.name.split("_")[0] in ours and p.name not in files]
    for name in stale:  # a setting taken out of a range above
        (out / name).unlink()
    for name, text in files.items():
        (out / name).write_text(text)
    print(f"wrote {len(files)} files into {out}" + (f", removed {len(stale)}" if stale else ""))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
