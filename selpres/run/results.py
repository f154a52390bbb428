"""What a job reports: ``results.json`` (identity, cost, timing, per-replica and summary metrics, curves).

A job's identity is the hash of everything that can change its numbers (``job_hash``); the knobs that
cannot (logging, threads, checkpoints, the sweep's name, overwrite) are left out, so changing them finds
the same finished job.
"""

from __future__ import annotations

import math
import subprocess
import time
from pathlib import Path

import torch
from omegaconf import DictConfig

from selpres.data.file import file_digest
from selpres.data.task import task_files
from selpres.engines.activations import ACTIVATIONS
from selpres.presentation.orders import REGISTRY as ORDERS
from selpres.presentation.sampler import shuffle_implementation
from selpres.run import floor, stalls
from selpres.run.optimizer import optim_spec
from selpres.run.specs import recorded, task_specs
from selpres.run.stats import summarize
from selpres.storage import stable_hash

NOT_IDENTITY = ("logging", "overwrite", "threads", "checkpoint", "name")
SETS = ("test10", "heldout")
UNITS = ("nm", "scaled", "nmse")  # nmse: MSE ÷ the set's target variance (selpres.run.floor)


def job_hash(cfg: DictConfig) -> str:
    """Identity of a job's numbers: everything but the knobs that cannot change them, and the contents of the
    files its task reads (``selpres.data.task.task_files``: what the arm's source reads, a data file), so an edited
    URDF or CSV is not taken for the finished job. The config as results.json records it (``recorded``: the data node
    typed by its route)."""
    c = recorded(cfg)
    for k in NOT_IDENTITY:
        c.pop(k, None)
    c["file_sha256"] = [file_digest(p) if p.is_file() else None for p in task_files(*task_specs(cfg))]
    return stable_hash(c)


def replica_results(seeds: list[int], final: dict, diverged_at: list, last_train_mse: list) -> list[dict]:
    """One entry per replica: its seed, status, final metrics (None once diverged) and last training MSE."""
    out = []
    for r, seed in enumerate(seeds):
        ok = diverged_at[r] is None
        metrics = {
            name: {unit: {k: _value(v[r]) if ok else None for k, v in ev[unit].items()} for unit in UNITS if unit in ev}
            for name, ev in final.items()
        }
        out.append(
            {
                "seed": seed,
                "status": "complete" if ok else "diverged",
                "diverged": diverged_at[r],
                "final": metrics,
                "train_mse": last_train_mse[r] if ok else None,
            }
        )
    return out


def _value(t) -> float | None:
    v = t.item()
    return v if math.isfinite(v) else None  # an nMSE of a target that does not vary


def unscored(final: dict, progress) -> None:
    """A replica whose final scores are not all finite (weights finite, errors overflowing) is not complete:
    it counts as diverged at the end, so no job is ``complete`` with null metrics."""
    for name, ev in final.items():
        for unit in ("nm", "scaled"):  # the errors; an nMSE is undefined (None) where a target does not vary
            for v in ev[unit].values():
                for r in (~torch.isfinite(v)).nonzero().flatten().tolist():
                    if progress.diverged_at[r] is None:
                        progress.diverged_at[r] = {
                            "epoch": progress.epoch,
                            "presentations": progress.presentations,
                            "reason": f"final {name} RMS ({unit}) not finite",
                        }


def summary(replicas: list[dict]) -> dict:
    """mean / std / 95 % interval over complete replicas of every final metric (overall, tau1..tauK)."""
    joints = list(replicas[0]["final"]["heldout"]["nm"]) if replicas else []
    return {
        f"{name}_rms_{unit}_{joint}": summarize(rep["final"][name][unit][joint] for rep in replicas)
        for name in SETS
        for unit in UNITS
        for joint in joints
        if unit in replicas[0]["final"][name]
    }


def build(cfg: DictConfig, chash: str, prob, engine, final: dict, progress, seconds: dict) -> dict:
    """results.json of a finished job (``prob``: selpres.run.problem.Problem; ``progress``: its Progress)."""
    R = len(prob.seeds)
    unscored(final, progress)
    reps = replica_results(prob.seeds, final, progress.diverged_at, progress.history[-1]["train_mse"])
    n_div = sum(d is not None for d in progress.diverged_at)
    heldout_n = int(prob.tests["heldout"][0].shape[0])
    training = sum(ep.presentations for ep in prob.plan[: progress.epoch])
    train_Y = prob.task.exemplar.Y if prob.task is not None else prob.scaler.inverse_y(prob.Y)
    task_floor = floor.task_floor(train_Y, prob.tests)
    stats = summary(reps)
    spec = optim_spec(cfg)
    pruning = prob.pruning.describe() if getattr(prob, "pruning", None) is not None else None
    order = {"order": cfg.schedule.order, "order_class": ORDERS.path_of(cfg.schedule.order)}  # the class that ran
    schedule = {"name": cfg.schedule.name, **order, **prob.schedule.describe()}
    if pruning is not None:  # what ran, not the plan's upper bound: mean over replicas (each in pruning)
        training = sum(pruning["trained_presentations"]) / R
        schedule.update(presentations=training, epochs=[max(pruning["epochs"])], planned_epochs=schedule["epochs"])
    return {
        "status": "diverged" if n_div == R else "complete",
        "diverged_replicas": n_div,
        "config_hash": chash,
        "schedule": schedule,
        "pruning": pruning,  # infobatch / selective_backprop: parameters, per-replica cost, patterns left out
        "topology": cfg.topology.layers,
        "engine": engine.name,  # what ran
        "optimizer": spec.path,  # the class whose rule ran (selpres.engines.optim, or the user's own)
        "optimizer_dropped": spec.dropped or None,  # keys of the optim group file the chosen class does not take
        "activation": ACTIVATIONS.path_of(cfg.model.activation),  # the hidden units' class that ran (a user's too)
        "engine_requested": cfg.engine.value,
        "engine_fallback": engine.fallback_reason,  # why "fast" did not run natively (None if it did)
        "evaluation": engine.evaluation,  # e.g. "native, 8 lanes (AVX-512)": the same numbers, not the same speed
        "shuffle": shuffle_implementation(),  # native, or numpy (why): the same permutations either way
        "replicas": R,
        "seeds": prob.seeds,
        "presentations_done": progress.presentations,  # the cost: training + selection presentations
        "training_presentations": training,
        "selection_presentations": progress.selection_presentations,  # forward passes (selpres.presentation.selection)
        "selection_cost": cfg.schedule.selection_cost,  # the charge per candidate scored
        "tests": {
            "test10": {"n": int(prob.tests["test10"][0].shape[0])},
            "heldout": {"n": heldout_n, "curve_n": min(cfg.eval.heldout_curve, heldout_n)},
            "heldout_curve_every": cfg.eval.every,
        },
        "data": prob.task.info if prob.task is not None else None,  # what data was made, how, its hash
        "schedule_note": prob.schedule_note,  # how a named schedule's counts were applied to this n
        "resumed_from_epoch": progress.resumed_from,
        "stale_checkpoint": progress.stale_checkpoint,
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "git_commit": _git_commit(),
        "wall_seconds": seconds,
        "seconds_per_presentation": seconds["train"] / max(1, training * R),
        "summary": stats,
        "floor": task_floor,  # predicting the training mean: RMS and nMSE per set and joint (selpres.run.floor)
        "floor_warnings": floor.floor_warnings(
            stats, task_floor, prob.task.info if prob.task else None, str(cfg.topology.layers)
        ),
        "replica_results": reps,
        "stalls": stalls.evidence(reps, engine, prob, cfg.model.activation, task_floor),  # stalled? dead units
        "curves": progress.history,
        "config": recorded(cfg),
    }


def _git_commit() -> str | None:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).parent,
            capture_output=True,
            text=True,
            timeout=5,
        )
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None
