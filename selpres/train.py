"""The training loop: one job trains R replicas of one (schedule, topology) through every stage.

Read top to bottom: ``prepare`` turns a config into a validated problem (data, schedule, samplers,
initial weights) without writing anything; ``train`` runs the epochs of the schedule's plan, asking each
replica's sampler for its presentation order and the engine for the updates, scores the test sets,
logs, checkpoints, and returns the results that ``results.json`` holds.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf

from selpres import data as D
from selpres.config import to_container, validate
from selpres.engine import make_engine
from selpres.errors import ConfigError
from selpres.model import forward_replicas, init_replica_params
from selpres.robot import TwoLinkArm
from selpres.sampler import SelectivePresentationSampler, epoch_orders, priority_order
from selpres.schedule import Schedule, build_schedule
from selpres.seeding import derive_seed, generator, seed_everything
from selpres.stats import summarize
from selpres.storage import CHECKPOINT, RESULTS, WEIGHTS, atomic_write, stable_hash, write_json
from selpres.tracking import Tracker



@dataclass
class Problem:
    """Everything a config determines before the first update."""

    sizes: tuple[int, ...]
    schedule: Schedule
    seeds: list[int]
    scaler: D.Scaler
    X: torch.Tensor  # exemplar inputs, scaled
    Y: torch.Tensor  # exemplar targets, scaled
    tests: dict  # name -> (X scaled, Y in Nm)
    samplers: list[SelectivePresentationSampler]
    init_params: list[torch.Tensor]


def job_hash(cfg: DictConfig) -> str:
    """Identity of a job's numbers: everything but the knobs that cannot change them."""
    c = to_container(cfg)
    for k in ("logging", "overwrite", "threads", "checkpoint", "name"):
        c.pop(k, None)
    return stable_hash(c)


@functools.lru_cache(maxsize=4)
def _exemplar(robot_json: str, data_json: str) -> D.ExemplarSet:
    """Cached per robot/data config, so the jobs of an in-process sweep (Hydra's basic launcher) build
    the data once. Cached tensors are never modified in place."""
    return D.build_exemplar_set(TwoLinkArm.from_config(json.loads(robot_json)), OmegaConf.create(json.loads(data_json)))


@functools.lru_cache(maxsize=4)
def _tests_and_scaler(robot_json: str, data_json: str) -> tuple[D.TestSets, D.Scaler]:
    arm, data_cfg = TwoLinkArm.from_config(json.loads(robot_json)), OmegaConf.create(json.loads(data_json))
    exemplar = _exemplar(robot_json, data_json)
    return D.make_test_sets(arm, data_cfg, exemplar, seed=data_cfg.test_seed), D.Scaler.fit(exemplar, data_cfg)


def prepare(cfg: DictConfig) -> Problem:
    sizes = validate(cfg)
    # plain values (enums as strings) for the data module
    keys = json.dumps(to_container(cfg.robot), sort_keys=True), json.dumps(to_container(cfg.data), sort_keys=True)
    exemplar = _exemplar(*keys)
    n = exemplar.X.shape[0]
    if n == 0:
        raise ConfigError(
            "data.accel_limit", cfg.data.accel_limit,
            f"a filter that keeps at least one of the {exemplar.n_candidates:,} grid candidates of "
            "data.theta/dtheta/tau1/tau2 (none has both |θ̈| within it: widen the limit or move the ranges)",
        )
    if cfg.data.test_from_exemplar > n:
        raise ConfigError("data.test_from_exemplar", cfg.data.test_from_exemplar,
                          f"at most the exemplar set's size n = {n}")
    try:
        tests, scaler = _tests_and_scaler(*keys)
    except ValueError as e:  # the continuous ranges leave nothing to draw test patterns from
        raise ConfigError("data", "theta/dtheta/tau1/tau2 ranges", str(e)) from None
    sch = to_container(cfg.schedule)
    schedule = build_schedule(sch["sizes"], sch["epochs"], n, sch["budget"])
    seeds = [cfg.seed + r for r in range(cfg.replicas)]
    kind, bins = cfg.schedule.order.value, cfg.schedule.strata_bins
    samplers = [
        SelectivePresentationSampler(priority_order(exemplar.X, kind, generator(s, "subset"), bins), schedule, s)
        for s in seeds
    ]
    return Problem(
        sizes=sizes,
        schedule=schedule,
        seeds=seeds,
        scaler=scaler,
        X=scaler.transform_x(exemplar.X),
        Y=scaler.transform_y(exemplar.Y),
        tests={name: (scaler.transform_x(p.X), p.Y) for name, p in (("test10", tests.test10), ("heldout", tests.heldout))},
        samplers=samplers,
        init_params=init_replica_params(sizes, [derive_seed(s, "init") for s in seeds]),
    )


def curve_rms(params: list[torch.Tensor], X: torch.Tensor, Y_nm: torch.Tensor, scaler: D.Scaler) -> list:
    """Overall RMS (Nm) of every replica, the one number a curve point needs (cheaper than ``evaluate``)."""
    with torch.no_grad():
        return _as_list(D.rms_overall_nm(forward_replicas(params, X), Y_nm, scaler))


def evaluate(params: list[torch.Tensor], X: torch.Tensor, Y_nm: torch.Tensor, scaler: D.Scaler) -> dict:
    """RMS errors of every replica on one test set, batched across replicas: {unit: {joint: [R]}}."""
    with torch.no_grad():
        flat = D.rms_errors(forward_replicas(params, X), Y_nm, scaler)
    return {unit: {j: flat[f"{j}_{u}"] for j in ("overall", "tau1", "tau2")} for unit, u in (("nm", "Nm"), ("scaled", "scaled"))}


def _as_list(t: torch.Tensor) -> list:
    return [v if math.isfinite(v) else None for v in t.tolist()]


def train(cfg: DictConfig, out_dir: str | Path | None = None) -> dict:
    """Train ``cfg.replicas`` replicas through the schedule; returns the results dict.

    With ``out_dir`` the job logs to TensorBoard, checkpoints and writes ``results.json`` there, and
    resumes from a checkpoint of the same config if one is present.
    """
    t_start = time.perf_counter()
    seed_everything(cfg.seed)
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    prob = prepare(cfg)
    chash = job_hash(cfg)
    out = Path(out_dir) if out_dir is not None else None
    R, plan = len(prob.seeds), prob.schedule.plan()
    stage_ends = set(prob.schedule.stage_ends())
    engine = make_engine(cfg.engine.value, prob.sizes, prob.init_params, cfg.optim.lr, cfg.optim.momentum, cfg.optim.batch_size)
    curve_X, curve_Y = (t[: cfg.eval.heldout_curve] for t in prob.tests["heldout"])

    history: list[dict] = []
    diverged_at: list[dict | None] = [None] * R
    start_epoch, presentations, train_seconds = 0, 0, 0.0
    ckpt_path = out / CHECKPOINT if out else None
    if ckpt_path is not None and ckpt_path.exists() and cfg.checkpoint.enabled:
        ck = torch.load(ckpt_path, weights_only=False)
        if ck["config_hash"] == chash:
            engine.load_state_dict(ck["engine"])
            history, diverged_at = json.loads(ck["history"]), ck["diverged_at"]
            start_epoch, presentations, train_seconds = ck["epoch"], ck["presentations"], ck["train_seconds"]
            print(f"resuming from {ckpt_path} at epoch {start_epoch}/{len(plan)}")
    tracker = Tracker(out / "tb", cfg.logging.tensorboard, cfg.logging.per_replica) if out else Tracker(Path("."), False)
    tracker.replay(history)

    def save_checkpoint(epoch_done: int) -> None:
        state = {
            "config_hash": chash, "epoch": epoch_done, "presentations": presentations,
            "train_seconds": train_seconds, "engine": engine.state_dict(),
            "history": json.dumps(history), "diverged_at": diverged_at,  # JSON: one object to pickle, not thousands
        }
        atomic_write(ckpt_path, lambda f: torch.save(state, f))

    if start_epoch == 0 and not history:  # the untrained network: every curve starts at 0 presentations
        params = engine.params()
        history.append({
            "epoch": -1, "stage": 0, "size": plan[0].size, "presentations": 0, "train_mse": [None] * R,
            "test10_rms_nm": curve_rms(params, *prob.tests["test10"], prob.scaler),
            "heldout_rms_nm": curve_rms(params, curve_X, curve_Y, prob.scaler),
        })
        tracker.log_epoch(history[0])

    t_loop = time.perf_counter()
    for ep in plan[start_epoch:]:
        for s in prob.samplers:
            s.set_epoch(ep.index)
        order = epoch_orders(prob.samplers)
        t0 = time.perf_counter()  # train_seconds times the updates alone: the paper's t per presentation
        loss = engine.train_epoch(prob.X, prob.Y, order)
        train_seconds += time.perf_counter() - t0
        presentations += ep.presentations

        params = engine.params()
        finite = torch.isfinite(loss) & torch.stack([torch.isfinite(p).flatten(1).all(1) for p in params]).all(0)
        for r in torch.nonzero(~finite).flatten().tolist():
            if diverged_at[r] is None:
                diverged_at[r] = {"epoch": ep.index + 1, "presentations": presentations}
        last = ep.index == len(plan) - 1
        rec = {
            "epoch": ep.index, "stage": ep.stage, "size": ep.size, "presentations": presentations,
            "train_mse": _as_list(loss),
            "test10_rms_nm": curve_rms(params, *prob.tests["test10"], prob.scaler),
            "heldout_rms_nm": None,
        }
        if ep.index in stage_ends or (cfg.eval.every and (ep.index + 1) % cfg.eval.every == 0):
            rec["heldout_rms_nm"] = curve_rms(params, curve_X, curve_Y, prob.scaler)
        history.append(rec)
        tracker.log_epoch(rec)
        if cfg.logging.progress and ep.index in stage_ends:
            _print_stage(rec, prob.schedule, R)
        if all(d is not None for d in diverged_at):  # nothing left to train: stop the job here
            print(f"every replica diverged by epoch {ep.index + 1}; stopping")
            break
        if out is not None and cfg.checkpoint.enabled and not last and (
            ep.index in stage_ends or (cfg.checkpoint.every and (ep.index + 1) % cfg.checkpoint.every == 0)
        ):
            save_checkpoint(ep.index + 1)
    loop_seconds = time.perf_counter() - t_loop

    params = engine.params()
    final = {name: evaluate(params, X, Y, prob.scaler) for name, (X, Y) in prob.tests.items()}
    results = _results(cfg, chash, prob, final, history, diverged_at, presentations,
                       train_seconds, loop_seconds, time.perf_counter() - t_start)
    if out is not None:
        # everything needed to use a trained net: load_into(BPN(topology), params, r) + the scaler's bounds
        trained = {"params": params, "seeds": prob.seeds, "topology": cfg.topology.layers,
                   "scaler": dataclasses.asdict(prob.scaler), "config_hash": chash}
        atomic_write(out / WEIGHTS, lambda f: torch.save(trained, f))
        write_json(out / RESULTS, results)
        if ckpt_path.exists():
            ckpt_path.unlink()
        hp = {"schedule": cfg.schedule.name, "topology": cfg.topology.layers, "seed": cfg.seed,
              "replicas": R, "lr": cfg.optim.lr, "momentum": cfg.optim.momentum,
              "batch_size": cfg.optim.batch_size, "sizes": str(prob.schedule.sizes),
              "epochs": str(prob.schedule.epochs), "order": cfg.schedule.order.value, "engine": cfg.engine.value}
        tracker.close(hp, {f"final/{k}": v["mean"] for k, v in results["summary"].items()})
    return results


def _results(cfg, chash, prob, final, history, diverged_at, presentations, train_s, loop_s, total_s) -> dict:
    R = len(prob.seeds)
    replicas = []
    for r, seed in enumerate(prob.seeds):
        ok = diverged_at[r] is None
        metrics = {
            name: {unit: {k: (v[r].item() if ok else None) for k, v in ev[unit].items()} for unit in ("nm", "scaled")}
            for name, ev in final.items()
        }
        replicas.append({
            "seed": seed, "status": "complete" if ok else "diverged", "diverged": diverged_at[r],
            "final": metrics, "train_mse": history[-1]["train_mse"][r] if ok else None,
        })
    summary = {}
    for name in final:
        for unit in ("nm", "scaled"):
            for joint in ("overall", "tau1", "tau2"):
                summary[f"{name}_rms_{unit}_{joint}"] = summarize(
                    rep["final"][name][unit][joint] for rep in replicas)
    n_div = sum(d is not None for d in diverged_at)
    return {
        "status": "diverged" if n_div == R else "complete",
        "diverged_replicas": n_div,
        "config_hash": chash,
        "schedule": {"name": cfg.schedule.name, "order": cfg.schedule.order.value, **prob.schedule.describe()},
        "topology": cfg.topology.layers,
        "engine": cfg.engine.value,
        "replicas": R,
        "seeds": prob.seeds,
        "presentations_done": presentations,
        "tests": {"test10": {"n": int(prob.tests["test10"][0].shape[0])},
                  "heldout": {"n": int(prob.tests["heldout"][0].shape[0]), "curve_n": min(cfg.eval.heldout_curve, int(prob.tests["heldout"][0].shape[0]))},
                  "heldout_curve_every": cfg.eval.every},
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "git_commit": _git_commit(),
        "wall_seconds": {"total": total_s, "train": train_s, "loop": loop_s},
        "seconds_per_presentation": train_s / max(1, presentations * R),
        "summary": summary,
        "replica_results": replicas,
        "curves": history,
        "config": to_container(cfg),
    }


def _git_commit() -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).parent,
                             capture_output=True, text=True, timeout=5)
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def _print_stage(rec: dict, schedule: Schedule, R: int) -> None:
    def mean(vals):
        f = [v for v in vals if v is not None]
        return sum(f) / len(f) if f else math.nan

    held = f"  held-out RMS {mean(rec['heldout_rms_nm']):.4f} Nm" if rec["heldout_rms_nm"] else ""
    print(
        f"stage {rec['stage'] + 1}/{len(schedule.stages)}  n_i={rec['size']:5d}  epoch {rec['epoch'] + 1:4d}  "
        f"presentations {rec['presentations']:7d}  train MSE {mean(rec['train_mse']):.3e}  "
        f"test-10 RMS {mean(rec['test10_rms_nm']):.4f} Nm{held}" + (f"  (mean of {R} replicas)" if R > 1 else ""),
        flush=True,
    )


def summary_table(results: dict) -> str:
    """The short table printed at the end of a job."""
    s, sch = results["summary"], results["schedule"]
    def fmt(key):
        m = s[key]
        if m["mean"] is None:
            return "n/a"
        return f"{m['mean']:.4f}" + (f" ± {m['std']:.4f}" if m["std"] is not None else "")
    rows = [
        ("schedule", f"{sch['name']} (p={sch['p']}, sizes {sch['sizes']}, epochs {sch['epochs']})"),
        ("topology", results["topology"]),
        ("replicas", f"{results['replicas']} (seeds {results['seeds'][0]}..{results['seeds'][-1]}), {results['diverged_replicas']} diverged"),
        ("cost T/t", f"{sch['presentations']:,} presentations  (T_con/t at equal epochs {sch['conventional_presentations']:,}; "
                     f"ratio {sch['cost_ratio']:.3f})"),
        ("wall time", f"{results['wall_seconds']['total']:.2f} s total, {results['wall_seconds']['train']:.2f} s in updates ({results['engine']} engine)"),
        ("test-10 RMS", f"{fmt('test10_rms_nm_overall')} Nm   {fmt('test10_rms_scaled_overall')} scaled"),
        ("held-out RMS", f"{fmt('heldout_rms_nm_overall')} Nm   {fmt('heldout_rms_scaled_overall')} scaled"),
    ]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)
