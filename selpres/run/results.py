"""What a job reports: ``results.json`` (identity, cost, timing, per-replica and summary metrics, curves).

The method is named by what ran (``selector``: the class that chose every epoch and the order it grew the sets by,
a user's by its import path) and its cost is what the job's ledger measured (``cost``: per replica, back-propagated
presentations and forward passes charged for choosing, over conventional training's presentations in the same
epochs), read the same way for every method; the ``schedule`` node's presentations, epochs and cost ratio are
those measured ones beside the plan's (``planned_epochs``).

A job's identity is the hash of everything that can change its numbers (``job_hash`` of a composed config; a
resolved job holds it as ``JobSpec.hash``, both ``selpres.run.specs.identity``); the knobs that cannot (logging,
threads, checkpoints, the sweep's name, overwrite) are left out, so changing them finds the same finished job.
"""

from __future__ import annotations

import math
import time

import torch
from omegaconf import DictConfig

from selpres.engines.activations import ACTIVATIONS
from selpres.engines.factory import Engine
from selpres.presentation.sampler import shuffle_implementation
from selpres.run import floor, provenance, stalls
from selpres.run.specs import JobSpec, identity, recorded, task_specs
from selpres.run.stats import summarize

SETS = ("test10", "heldout")
UNITS = ("nm", "scaled", "nmse")  # nmse: MSE ÷ the set's target variance (selpres.run.floor)


def job_hash(cfg: DictConfig) -> str:
    """The identity of a composed config's job (``selpres.run.specs.identity``): what a job resolved from it records
    as ``config_hash``, so the command line finds a finished job without resolving it."""
    return identity(recorded(cfg), *task_specs(cfg))


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


def build(job: JobSpec, prob, engine: Engine, final: dict, progress, seconds: dict) -> dict:
    """results.json of a finished job (``prob``: selpres.run.problem.Problem; ``progress``: its Progress)."""
    R = len(prob.seeds)
    unscored(final, progress)
    reps = replica_results(prob.seeds, final, progress.diverged_at, progress.history[-1]["train_mse"])
    n_div = sum(d is not None for d in progress.diverged_at)
    heldout_n = int(prob.tests["heldout"][0].shape[0])
    train_Y = prob.task.exemplar.Y if prob.task is not None else prob.scaler.inverse_y(prob.Y)
    task_floor = floor.task_floor(train_Y, prob.tests)
    stats = summary(reps)
    cost = prob.ledger.describe()
    training = cost["trained_presentations"]  # what ran: mean over replicas (each in cost.per_replica)
    sel = prob.selector
    selector = {**sel.identity, **sel.describe(), "checkpointed": job.checkpoints}
    schedule = {
        "name": job.schedule.name,
        "order": job.schedule.selector.order,
        "order_class": sel.identity["order_class"],  # the class that ran
        **prob.schedule.describe(),
        "presentations": training,
        "epochs": epochs_run(prob.schedule, max(cost["per_replica"]["epochs"], default=0)),
        "planned_epochs": prob.schedule.epochs,
        "conventional_presentations": cost["conventional_presentations"],
        "cost_ratio": cost["cost_ratio"],  # measured: presented and charged over conventional's
    }
    return {
        "status": "diverged" if n_div == R else "complete",
        "diverged_replicas": n_div,
        "config_hash": job.hash,
        "schedule": schedule,
        "selector": selector,  # what chose every epoch's patterns: its name, class, parameters
        "cost": cost,  # the ledger: per replica and mean, presentations trained and charged, the cost ratio
        "topology": job.layers,
        "engine": engine.name,  # what ran
        "optimizer": job.optim.path,  # the class whose rule ran (selpres.engines.optim, or the user's own)
        "activation": ACTIVATIONS.path_of(job.activation),  # the hidden units' class that ran (a user's too)
        "engine_requested": job.engine.requested,
        "engine_fallback": engine.fallback_reason,  # why "fast" did not run natively (None if it did)
        "evaluation": engine.evaluation,  # e.g. "native, 8 lanes (AVX-512)": the same numbers, not the same speed
        "shuffle": shuffle_implementation(),  # native, or numpy (why): the same permutations either way
        "replicas": R,
        "seeds": prob.seeds,
        "presentations_done": progress.presentations,  # the cost: training + selection presentations
        "training_presentations": training,
        "selection_presentations": progress.selection_presentations,  # forward passes (selpres.presentation.selection)
        "selection_cost": job.schedule.selector.selection_cost,  # the charge per candidate scored
        "tests": {
            "test10": {"n": int(prob.tests["test10"][0].shape[0])},
            "heldout": {"n": heldout_n, "curve_n": min(job.cadence.heldout_curve, heldout_n)},
            "heldout_curve_every": job.cadence.heldout_every,
        },
        "data": prob.task.info if prob.task is not None else None,  # what data was made, how, its hash
        "schedule_note": prob.schedule_note,  # how a named schedule's counts were applied to this n
        "resumed_from_epoch": progress.resumed_from,
        "stale_checkpoint": progress.stale_checkpoint,
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "provenance": provenance.record(),  # versions, commit (selpres's own checkout only), platform, native build
        "wall_seconds": seconds,
        "seconds_per_presentation": seconds["train"] / max(1, training * R),
        "summary": stats,
        "floor": task_floor,  # predicting the training mean: RMS and nMSE per set and joint (selpres.run.floor)
        "floor_warnings": floor.floor_warnings(
            stats, task_floor, prob.task.info if prob.task else None, str(job.layers)
        ),
        "replica_results": reps,
        "stalls": stalls.evidence(reps, engine, prob, job.activation, task_floor),  # stalled? dead units
        "curves": progress.history,
        "config": job.config,
    }


def epochs_run(schedule, epochs: int) -> list[int]:
    """The full epochs run in each stage when ``epochs`` epochs of the plan ran (a partial epoch is the stage's
    ``extra``, not an epoch)."""
    out = []
    for st in schedule.stages:
        full = min(st.epochs, epochs)
        out.append(full)
        epochs -= full + (1 if st.extra and epochs > st.epochs else 0)
    return out
