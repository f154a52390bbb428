"""Partners of a sweep: conventional training at every cost the sweep contains, so every setting is compared at
equal cost (``partners=on``, ``configs/partners/``).

A staged setting's *compute-matched partner* is one-stage conventional training stopped at the same presentations
(training plus the charge for choosing), with the same other settings; the *full conventional run* is the paper's
conventional method (all n patterns, N = ΣN_i epochs: the sweep's own total where its settings share one, else
the conventional preset's 150). After the sweep's own jobs (:class:`Partners`, a Hydra callback that does nothing
unless ``partners=on``), the costs are read from the finished jobs' results.json and the partners run as one more
sweep into ``<sweep>/partners/``, with the sweep's overrides outside the schedule (a swept topology or rate is
swept there too) and its launcher: conventional training stopped at each budget, ``schedule=stages
schedule.p=0 schedule.budget=...`` named ``conventional`` (a budget there is not rescaled to n, as the ``matched``
preset's paper count is); the full run is the budget n·N, whole epochs: the same stages, the same numbers, as
``schedule=conventional``. A partner that already ran is found done, as any job of a re-run sweep.

The report names the partners a sweep lacks and prints :func:`rerun_command`: the sweep's own command with
``partners=on``, which finds the sweep's jobs done and adds only the partners.
"""

from __future__ import annotations

import json
import logging
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

log = logging.getLogger("selpres")

FOLDER = "partners"  # <sweep>/partners/: where the partners run
FULL_EPOCHS = 150  # the conventional preset's N (configs/schedule/conventional.yaml)


def _schedule_override(item: str) -> bool:
    key = item.lstrip("+~").split("=", 1)[0]
    return key in ("schedule", "design", "partners") or key.startswith("schedule.")


def costs(sweep: Path) -> list[int]:
    """The budgets of the sweep's partners, sorted: the cost of each of its staged settings, and n·N of its full
    conventional run; read from its finished jobs (those under ``<sweep>/partners/`` left out)."""
    budgets, totals, n = set(), set(), None
    for path in sweep.rglob("results.json"):
        if FOLDER in path.relative_to(sweep).parts[:-1]:
            continue
        try:
            res = json.loads(path.read_bytes())
            sch = res["schedule"]
            n = sch["sizes"][-1]
        except (OSError, ValueError, KeyError, TypeError, IndexError):
            continue
        if res.get("status") != "complete" or res.get("pruning") or len(sch["sizes"]) < 2:
            continue
        budgets.add(int(res["presentations_done"]))
        if not any(sch.get("extra_presentations") or []) and sch.get("budget") is None:
            totals.add(sum(sch["epochs"]))
    if n is None:
        return []
    return sorted(budgets | {n * (totals.pop() if len(totals) == 1 else FULL_EPOCHS)})


def partner_sweep(task: list[str], launcher: str | None, budgets: list[int], sweep: Path) -> list[str]:
    """The command line (an argument list) of the partners' sweep: conventional training stopped at each budget."""
    base = [o for o in task if not _schedule_override(o)]
    base += [f"hydra/launcher={launcher}"] if launcher and launcher != "basic" else []
    base += [f"hydra.sweep.dir={sweep / FOLDER}", "hydra.sweeper.params={}"]
    one_stage = ["schedule=stages", "schedule.name=conventional", "schedule.p=0", "schedule.first=null"]
    one_stage += ["schedule.growth=null", "schedule.total_epochs=null", f"schedule.budget={','.join(map(str, budgets))}"]
    return [sys.executable, "-m", "selpres.run.main", "-m", *base, *one_stage]


class Partners(Callback):
    """Hydra callback: with ``partners=on``, the sweep's partners after its own jobs (see the module's docstring)."""

    def __init__(self, enabled: bool = False):
        self.enabled = bool(enabled)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        if not self.enabled:
            return
        sweep = Path(str(OmegaConf.select(config, "hydra.sweep.dir")))
        budgets = costs(sweep)
        if not budgets:
            log.warning("partners: no finished job in %s to take a cost from", sweep)
            return
        task = list(OmegaConf.select(config, "hydra.overrides.task") or [])
        launcher = OmegaConf.select(config, "hydra.runtime.choices.hydra/launcher")
        argv = partner_sweep(task, launcher, budgets, sweep)
        log.info("partners: conventional training stopped at %s presentations, in %s",
                 ", ".join(f"{b:,}" for b in budgets), sweep / FOLDER)  # fmt: skip
        done = subprocess.run(argv, check=False)
        if done.returncode != 0:
            log.warning("partners: %s exited %d", shlex.join(argv[3:]), done.returncode)


def rerun_command(sweep: Path) -> str | None:
    """The sweep's own command with ``partners=on`` (from its multirun.yaml), which adds only the partners; None for
    folders gathered by hand."""
    try:
        hydra = OmegaConf.load(sweep / "multirun.yaml").hydra
        task = [o for o in OmegaConf.select(hydra, "overrides.task") or [] if not o.startswith("partners=")]
        launcher = OmegaConf.select(hydra, "runtime.choices.hydra/launcher")
    except Exception:
        return None
    extra = [f"hydra/launcher={launcher}"] if launcher and launcher != "basic" else []
    return shlex.join(["python", "train.py", "-m", *task, *extra, "partners=on"])
