"""The training loop: one job trains R replicas of one (schedule, topology) through every stage.

Read top to bottom: ``train`` resolves the config into a checked job (``selpres.run.resolve``: read once, never
again), ``prepare`` (``selpres.run.problem``) turns that into a validated problem (data, schedule, the selector and
its ledger, initial weights) without writing anything; the loop runs the epochs of the schedule's plan, asking the
selector what each replica presents (``selpres.presentation.selector``: the same question of every method) and the
engine for the updates, charges the ledger, scores the test sets, logs, checkpoints, and returns the results that
``results.json`` holds.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch
from omegaconf import DictConfig

from selpres.engines.factory import Engine
from selpres.patterns import metric_names
from selpres.presentation.sampler import shuffle_implementation
from selpres.presentation.schedule import EpochPlan
from selpres.presentation.selector import Network
from selpres.run import floor, lock, orphan, stop
from selpres.run import results as results_json
from selpres.run.checkpoint import Checkpoints, Progress
from selpres.run.hparams import close_job
from selpres.run.problem import Problem, job_engine, prepare
from selpres.run.resolve import resolve
from selpres.run.specs import Cadence, JobSpec
from selpres.run.tracking import Tracker
from selpres.seeding import seed_everything
from selpres.storage import RESULTS, WEIGHTS, atomic_write, write_json

log = logging.getLogger("selpres")


WORK = frozenset(("select", "shuffle", "train"))  # a method's own phases (Clock.work)


class _Phase:
    """One timed phase: a plain context manager, since the loop opens several every epoch."""

    __slots__ = ("clock", "name", "t0", "inner0")

    def __init__(self, clock: Clock, name: str):
        self.clock, self.name = clock, name

    def __enter__(self):
        self.t0, self.inner0 = time.perf_counter(), self.clock._inner

    def __exit__(self, *exc):
        c, dt = self.clock, time.perf_counter() - self.t0
        if self.name in WORK:  # less the work phases closed inside it; then all of it is closed work
            c.seconds[self.name] += dt - (c._inner - self.inner0)
            c._inner = self.inner0 + dt
        else:
            c.seconds[self.name] += dt


class Clock:
    """Seconds per named phase of a job (``with clock("eval"): ...``), accumulated over resumes. A method's own
    phases (``WORK``) nest: one opened inside another (the shuffles inside choosing) takes its seconds from the
    outer one, so each second is counted once."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self._t0 = time.perf_counter()
        self._inner = 0.0  # seconds of work phases closed so far

    def __call__(self, phase: str) -> _Phase:
        return _Phase(self, phase)

    def add(self, earlier: dict) -> None:
        """Count the seconds of an earlier process of this job (from its checkpoint)."""
        for k, v in earlier.items():
            self.seconds[k] += v

    def work(self) -> float:
        """The method's own seconds so far: choosing, shuffling and training (not evaluation, logging or saving),
        so that wall time to a given error can be read off the curve."""
        return sum(self.seconds.get(k, 0.0) for k in WORK)  # .get: a phase that never ran is not recorded

    def snapshot(self) -> dict:
        """The phases so far, and ``total``: wall seconds of this job, earlier processes included."""
        total = self.seconds["total"] + time.perf_counter() - self._t0
        return {**self.seconds, "total": total}


def _as_list(t: torch.Tensor) -> list:
    return [v if math.isfinite(v) else None for v in t.tolist()]


def _rms(sums: torch.Tensor, n: int) -> torch.Tensor:
    """Overall RMS of every replica from its per-output sums of squared errors [R, out] over n patterns."""
    return sums.sum(1).div(n * sums.shape[1]).sqrt()


def _rms_nm(sums: torch.Tensor, n: int, prob: Problem) -> torch.Tensor:
    """Overall RMS in Nm from sums of squared *scaled* errors [R, out]."""
    return _rms(sums * prob.nm2_per_scaled2, n)


def curve_point(engine, prob: Problem, cad: Cadence, ep: EpochPlan | None, loss, progress: Progress) -> dict:
    """One history record: where the job is, the training MSE, test-10 RMS and (when due) held-out RMS."""
    epoch = -1 if ep is None else ep.index
    every = cad.heldout_every
    heldout_due = ep is None or epoch in prob.stage_ends or (every and (epoch + 1) % every == 0)
    rms = lambda X, Y: _as_list(_rms_nm(engine.squared_errors(X, Y), X.shape[0], prob))
    return {
        "epoch": epoch,
        "stage": 0 if ep is None else ep.stage,
        "size": (ep or prob.plan[0]).size,
        "presentations": progress.presentations,
        "train_mse": [None] * len(prob.seeds) if loss is None else _as_list(loss),
        "test10_rms_nm": rms(*prob.scored["test10"]),
        "heldout_rms_nm": rms(*(t[: cad.heldout_curve] for t in prob.scored["heldout"])) if heldout_due else None,
    }


def mark_diverged(progress: Progress, engine, loss: torch.Tensor, epoch: int) -> None:
    """A replica whose loss or weights are no longer finite diverged here (its results are withheld)."""
    if math.isfinite(float(loss.sum())) and bool(engine.finite().all()):  # the usual case, in few small ops
        return  # (a sum that overflows while every loss is finite only takes the slow path below)
    finite = torch.isfinite(loss) & engine.finite()
    for r in torch.nonzero(~finite).flatten().tolist():
        if progress.diverged_at[r] is None:
            progress.diverged_at[r] = {"epoch": epoch + 1, "presentations": progress.presentations}


def final_scores(engine, prob: Problem) -> dict:
    """RMS of every replica on each test set, per joint and overall, in Nm and scaled units, and its nMSE."""
    out = {}
    for name, (X, Y) in prob.scored.items():
        sums, n = engine.squared_errors(X, Y), X.shape[0]  # [R, out] in scaled units
        scores = {}
        for unit, unit_sums in (("nm", sums * prob.nm2_per_scaled2), ("scaled", sums)):
            per_joint = unit_sums.div(n).sqrt()
            scores[unit] = {
                "overall": _rms(unit_sums, n),
                **{joint: per_joint[:, k] for k, joint in enumerate(metric_names(sums.shape[1])[1:])},
            }
        scores["nmse"] = floor.nmse(sums * prob.nm2_per_scaled2, n, prob.tests[name][1])  # selpres.run.floor
        out[name] = scores
    return out


@dataclass
class Job:
    """A job under way: its problem, engine, progress and where it writes (``out`` None: nowhere)."""

    spec: JobSpec
    prob: Problem
    engine: Engine
    progress: Progress
    out: Path | None
    ckpts: Checkpoints | None
    tracker: Tracker
    net: Network  # the replicas' networks as the selector may ask them, and the clock

    def checkpoint_due(self, ep: EpochPlan) -> bool:
        every = self.spec.cadence.checkpoint_every
        every = every and (ep.index + 1) % every == 0
        last = ep.index == len(self.prob.plan) - 1
        return self.ckpts is not None and not last and (ep.index in self.prob.stage_ends or bool(every))


def start(spec: JobSpec, out_dir: str | Path | None, clock: Clock) -> Job:
    """Prepare the resolved job; resume from its checkpoint if there is one (overwrite: start afresh)."""
    seed_everything(spec.seed)
    if spec.threads > 0:
        torch.set_num_threads(spec.threads)
    prob = prepare(spec)
    engine = job_engine(spec, prob)
    if shuffle_implementation() != "native":
        log.warning("the per-epoch shuffles run in numpy (slower, the same permutations): %s", shuffle_implementation())
    out = Path(out_dir) if out_dir is not None else None
    parts = {"selector": prob.selector, "ledger": prob.ledger}  # every method's state: every job resumes exactly
    ckpts = Checkpoints(out, spec.hash, parts) if out is not None and spec.checkpoints else None
    if ckpts and spec.overwrite:
        ckpts.discard()
    progress = ckpts.resume(engine, len(prob.seeds)) if ckpts else Progress.fresh(len(prob.seeds))
    clock.add(progress.seconds)
    # the event file goes into the job's own folder: TensorBoard names the run by it (the overrides), not '…/tb'
    tracker = Tracker(out if out else Path("tb"), spec.tensorboard and out is not None, spec.per_replica)
    tracker.replay(progress.history)
    job = Job(spec, prob, engine, progress, out, ckpts, tracker, Network(engine, prob.X, prob.Y, clock))
    if not progress.history:  # the untrained network: every curve starts at 0 presentations
        record(job, {**curve_point(engine, prob, job.spec.cadence, None, None, progress), "work_seconds": 0.0})
    return job


def record(job: Job, rec: dict) -> None:
    job.progress.history.append(rec)
    job.tracker.log_epoch(rec)


def run_epoch(job: Job, ep: EpochPlan, clock: Clock) -> dict:
    """One epoch, of every method: the selector's presentations (each replica's patterns and weights; what
    choosing them cost is charged to the ledger), the engine's one epoch call, the ledger charged with what was
    presented, the selector shown the losses, then scoring."""
    prob, progress, ledger = job.prob, job.progress, job.prob.ledger
    with clock("select"):
        shown = prob.selector.select(ep, ledger, job.net)
    with clock("train"):
        loss = job.engine.train_epoch(
            prob.X, prob.Y, shown.order, weights=shown.weights, counts=shown.counts, spent=ledger.clock()
        )
    ledger.record(shown, ep)
    prob.selector.observe(shown, job.engine.last_losses)  # [R, m] after a pruned epoch, else [R, 0]
    progress.epoch = ep.index + 1
    # whole presentations on the curve (each replica's exact cost: results.json's cost)
    progress.presentations = round(ledger.mean("spent"))
    progress.selection_presentations = round(ledger.mean("charged"))
    with clock("eval"):
        mark_diverged(progress, job.engine, shown.presented(loss), ep.index)
        rec = curve_point(job.engine, prob, job.spec.cadence, ep, loss, progress)
    rec["work_seconds"] = clock.work()
    with clock("log"):
        record(job, rec)
    return rec


def train(
    cfg: DictConfig,
    out_dir: str | Path | None = None,
    on_stage_end: Callable[[dict, Problem], None] | None = None,
    on_epoch: Callable[[dict, Problem], None] | None = None,
) -> dict:
    """Train ``cfg.replicas`` replicas through the schedule of the composed config ``cfg``; returns the results dict.
    Its first step resolves ``cfg`` into a checked :class:`~selpres.run.resolve.JobSpec`: what follows reads that.

    With ``out_dir`` the job logs to TensorBoard, checkpoints and writes ``results.json`` and ``weights.pt``
    there, and resumes from a checkpoint of the same config (``overwrite=true``: starts afresh).
    ``on_stage_end(record, problem)`` is called at each stage's last epoch (the command line prints it);
    ``on_epoch(record, problem)`` after every epoch, before ``on_stage_end`` (the command line's progress line).
    """
    with lock.holding(out_dir):  # one writer per job folder (selpres.run.lock)
        clock = Clock()
        with clock("prepare"):
            job = start(resolve(cfg), out_dir, clock)
        with clock("loop"), stop.loop():
            for ep in job.prob.plan[job.progress.epoch :]:
                rec = run_epoch(job, ep, clock)
                if on_epoch is not None:
                    on_epoch(rec, job.prob)
                spent = job.prob.ledger.exhausted  # every replica spent its budget
                if on_stage_end is not None and (ep.index in job.prob.stage_ends or spent):
                    on_stage_end(rec, job.prob)
                if job.progress.all_diverged:  # nothing left to train: stop the job here
                    log.warning("every replica diverged by epoch %d; stopping", ep.index + 1)
                    break
                if spent:
                    break
                due, more = job.checkpoint_due(ep), ep.index < len(job.prob.plan) - 1
                stopping = stop.requested() is not None or (more and orphan.gone())  # a signal, or the sweep gone
                if due or (stopping and job.ckpts is not None):
                    with clock("checkpoint"):
                        job.progress.seconds = clock.snapshot()
                        job.ckpts.save(job.engine, job.progress)
                        job.tracker.flush()
                if stopping:  # what was kept is said by selpres.run.job
                    if stop.requested() is not None:
                        raise stop.Interrupted(stop.requested(), f"after epoch {ep.index + 1}")
                    raise orphan.SweepGone(f"after epoch {ep.index + 1}")
        with clock("eval"):
            final = final_scores(job.engine, job.prob)
        return finish(job, final, clock.snapshot())


def finish(job: Job, final: dict, seconds: dict) -> dict:
    """results.json, weights.pt (everything needed to use a trained net: load_into(BPN(topology), params, r)
    + the scaler) and the TensorBoard hparams; the checkpoint is no longer needed."""
    spec, prob = job.spec, job.prob
    results = results_json.build(spec, prob, job.engine, final, job.progress, seconds)
    for line in results["floor_warnings"]:
        log.warning("%s", line)
    if job.out is None:
        return results
    trained = {
        "params": job.engine.params(),
        "seeds": prob.seeds,
        "topology": spec.layers,
        "activation": spec.activation,  # load_into(BPN(topology, activation=...), params, r)
        "scaler": dataclasses.asdict(prob.scaler),
        "config_hash": spec.hash,
    }
    atomic_write(job.out / WEIGHTS, lambda f: torch.save(trained, f))
    write_json(job.out / RESULTS, results)
    close_job(job.tracker, results, job.out)  # HParams, final metrics (selpres.run.tracking)
    if job.ckpts:
        job.ckpts.discard()
    return results
