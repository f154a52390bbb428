"""Partners of a sweep: conventional training at every cost the sweep contains, so every setting is compared at
equal cost (``partners=on``, ``configs/partners/``).

A staged setting's *compute-matched partner* is one-stage conventional training stopped at the same presentations
(training plus the charge for choosing), with the same other settings; the *full conventional run* is the paper's
conventional method (all n patterns, N = ΣN_i epochs: the sweep's own total where its settings share one, else
the conventional preset's 150). ``partners=on`` makes the sweep's sweeper
``hydra_plugins.selpres_partners.PartnerSweeper``, Hydra's basic sweeper that, once the sweep's own jobs have run,
reads their costs from results.json and launches the partners through the same launcher (``hydra/launcher=local2``'s
workers are warm by then) into the same sweep folder: the sweep's overrides outside the schedule (a swept topology
or rate is swept there too) with conventional training stopped at each budget, ``schedule=stages schedule.p=0
schedule.budget=...`` named ``conventional`` (a budget there is not rescaled to n, as the ``matched`` preset's paper
count is); the full run is the budget n·N, whole epochs: the same stages, the same numbers, as
``schedule=conventional``. A partner that already ran is found done, as any job of a re-run sweep.

The report names the partners a sweep lacks and prints :func:`rerun_command`: the sweep's own command with
``partners=on``, which finds the sweep's jobs done and adds only the partners.
"""

from __future__ import annotations

import json
import os
import shlex
import sys
from pathlib import Path
from typing import Any

from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from selpres.run.legacy import selector_and_cost

FULL_EPOCHS = 150  # the conventional preset's N (configs/schedule/conventional.yaml)


def _schedule_override(item: str) -> bool:
    key = item.lstrip("+~").split("=", 1)[0]
    return key in ("schedule", "design", "partners") or key.startswith("schedule.")


def costs(sweep: Path) -> list[int]:
    """The budgets of the sweep's partners, sorted: the cost of each of its staged settings (more than one stage,
    every replica's measured cost the same), and n·N of its full conventional run; read from its finished jobs."""
    budgets, totals, n = set(), set(), None
    for path in sweep.rglob("results.json"):
        try:
            res = json.loads(path.read_bytes())
            sch = res["schedule"]
            n = sch["sizes"][-1]
            spent = selector_and_cost(res)[1]["per_replica"]["spent"]  # each replica's measured cost
        except (OSError, ValueError, KeyError, TypeError, IndexError):
            continue
        if res.get("status") != "complete" or len(sch["sizes"]) < 2 or len(set(spent)) != 1:
            continue  # one stage, or replicas that cost differently (one seed's choices): no one budget to match
        budgets.add(int(res["presentations_done"]))
        if not any(sch.get("extra_presentations") or []) and sch.get("budget") is None:
            totals.add(sum(sch["epochs"]))
    if not budgets:
        return []
    return sorted(budgets | {n * (totals.pop() if len(totals) == 1 else FULL_EPOCHS)})


def partner_overrides(given: list[str], budgets: list[int]) -> list[str]:
    """The partners' sweep: ``given`` (the sweep's overrides and params) outside the schedule, and conventional
    training stopped at each budget."""
    one_stage = ["schedule=stages", "schedule.name=conventional", "schedule.p=0", "schedule.first=null"]
    one_stage += [
        "schedule.growth=null",
        "schedule.total_epochs=null",
        f"schedule.budget={','.join(map(str, budgets))}",
    ]
    return [o for o in given if not _schedule_override(o)] + one_stage


def add_partners(sweeper: Any, arguments: list[str], returns: list) -> list:
    """After a basic sweeper's own jobs (``hydra_plugins.selpres_partners.PartnerSweeper``): the partners, through
    its launcher; ``returns`` with their results appended."""
    sweep = Path(str(OmegaConf.select(sweeper.config, "hydra.sweep.dir")))
    budgets = costs(sweep)
    if not budgets:
        print(f"partners: no staged job of {sweep} finished, so no cost to match", file=sys.stderr)
        return returns
    parser = OverridesParser.create(config_loader=sweeper.hydra_context.config_loader)
    given = parser.parse_overrides(partner_overrides(sweeper._parse_config() + list(arguments), budgets))
    jobs = [job for batch in sweeper.split_arguments(given, None) for job in batch]
    listed = ", ".join(f"{b:,}" for b in budgets)  # on the sweep's console (its process logs only Hydra's lines)
    print(f"partners: conventional training stopped at {listed} presentations ({len(jobs)} jobs)", file=sys.stderr)
    _more_jobs(len(jobs))
    returns.append(sweeper.launcher.launch(jobs, initial_job_idx=sum(len(r) for r in returns)))
    return returns


def _more_jobs(k: int) -> None:
    """Tell the sweep's progress line (selpres.run.progress) that ``k`` more jobs follow."""
    from selpres.run import progress

    path = os.environ.get(progress.ENV)
    if path:
        try:
            with open(path, "a") as f:
                f.write(json.dumps({"more": k}) + "\n")
        except OSError:
            pass


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
