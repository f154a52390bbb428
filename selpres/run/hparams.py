"""TensorBoard's view of a sweep: each job's hyperparameters and final metrics, and the sweep's HParams experiment.

What a sweep is compared by (:func:`close_job`, at a job's end): the HParams tab holds each job's schedule in the
parametric schedule's words, as numbers where they are numbers (p, n_1, ΣN_i, the cost in presentations and its
ratio to conventional training at equal epochs; the growth, the N_i rule and the order as text), beside the job's
own overrides (``.hydra/overrides.yaml``: the sweep's keys); its metrics are the *final* held-out RMS and nMSE (all
held-out patterns, mean over replicas) and test-10 RMS, scalars at one step, the job's cost, so the Time Series card
``final`` is the sweep's error–cost scatter; every final metric is also in a Markdown table in the Text tab.

TensorBoard takes the first experiment (the columns and metrics) it finds in any run, so a job writes none: after a
sweep, :class:`SweepHParams` (a Hydra callback in ``configs/train.yaml``) writes one at the sweep's root, every
hyperparameter any job has, the final metrics declared, and those that carry the sweep (p, n_1, the growth, the N_i
rule, ΣN_i, the cost, and the overrides every job has) marked as differing where they do: TensorBoard shows those
columns first. A single run's is inferred by TensorBoard from its session.
"""

from __future__ import annotations

import logging
import socket
import time
from pathlib import Path

from hydra.experimental.callback import Callback

from selpres.run.tracking import _HPARAMS_PLUGIN, _HPARAMS_TAGS, EventFile, Tracker, hparams_and_metrics

log = logging.getLogger("selpres")

FINAL = {  # the HParams metrics: a scalar each at the job's cost -> the results.json summary it is the mean of
    "final/heldout_rms_nm": "heldout_rms_nm_overall",
    "final/heldout_nmse": "heldout_rms_nmse_overall",
    "final/test10_rms_nm": "test10_rms_nm_overall",
}


def _number(text: str):
    """An override's value as TensorBoard's HParams should hold it: a number where it is one, else its text."""
    import yaml

    try:
        v = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    return v if isinstance(v, (int, float, bool)) else text


def overrides_of(folder: Path | None) -> dict:
    """The job's own overrides (Hydra's ``.hydra/overrides.yaml``: what the sweep set) as {key: value}."""
    path = None if folder is None else folder / ".hydra" / "overrides.yaml"
    try:
        import yaml

        given = yaml.safe_load(path.read_text()) if path and path.is_file() else []
    except (OSError, ValueError):
        return {}
    out = {}
    for item in given if isinstance(given, list) else []:
        key, eq, value = str(item).lstrip("+").partition("=")
        if eq and not key.startswith("~"):
            out[key] = _number(value)
    return out


def job_hparams(results: dict, folder: Path | None) -> dict:
    """A finished job's hyperparameters for the HParams tab: its schedule in the parametric schedule's words, its
    cost, the rest of what identifies it, then its own overrides (numbers as numbers)."""
    cfg, sch = results.get("config") or {}, results["schedule"]
    optim = cfg.get("optim") or {}
    hp = {
        "schedule": sch["name"],
        "selector": (results.get("selector") or {}).get("name"),  # what chose the epochs (a user's: its import path)
        "order": sch.get("order"),
        "p": sch.get("p"),
        "n1": sch.get("n1"),
        "growth": sch.get("growth"),
        "N_i rule": sch.get("profile"),
        "sum N_i": sch.get("epochs_total"),
        "budget": sch.get("budget"),
        "cost (presentations)": results.get("presentations_done"),
        "cost / conventional at equal epochs": sch.get("cost_ratio"),
        "topology": results.get("topology"),
        "seed": cfg.get("seed"),
        "replicas": results.get("replicas"),
        "optim": optim.get("_target_"),
        "lr": optim.get("lr"),
        "momentum": optim.get("momentum"),
        "batch_size": optim.get("batch_size"),
        "sizes": str(sch.get("sizes")),
        "epochs": str(sch.get("epochs")),
        "engine": results.get("engine"),
        "engine_requested": results.get("engine_requested"),
    }
    return {**hp, **overrides_of(folder)}


CORE = ("p", "n1", "growth", "N_i rule", "sum N_i", "cost (presentations)")  # shown first where they vary


def sweep_experiment(jobs: list[tuple[dict, dict]]):
    """The HParams experiment of a sweep, from its jobs' [(hyperparameters, overrides)]: every hyperparameter any job
    has, numbers as numbers and text with its values listed; those of :data:`CORE` and the overrides that every job
    has and that take two values or more marked as differing (TensorBoard shows those first, five at once); the
    final metrics declared."""
    from google.protobuf import struct_pb2
    from tensorboard.plugins.hparams import api_pb2

    values: dict[str, list] = {}
    for hp, _ in jobs:
        for k, v in hparams_and_metrics(hp, {})[0].items():
            values.setdefault(k, []).append(v)
    shared = set.intersection(*(set(o) for _, o in jobs)) if jobs else set()
    infos = []
    for name, vals in sorted(values.items()):
        vals = [v for v in vals if v is not None]
        if not vals:
            continue
        numeric = all(isinstance(v, (int, float)) for v in vals)
        info = api_pb2.HParamInfo(
            name=name,
            type=api_pb2.DataType.Value("DATA_TYPE_FLOAT64" if numeric else "DATA_TYPE_STRING"),
            differs=(name in CORE or name in shared) and len(vals) == len(jobs) and len(set(map(str, vals))) > 1,
        )
        if not numeric:
            info.domain_discrete.CopyFrom(
                struct_pb2.ListValue(
                    values=[struct_pb2.Value(string_value=str(v)) for v in sorted(set(map(str, vals)))]
                )
            )
        infos.append(info)
    metrics = [api_pb2.MetricInfo(name=api_pb2.MetricName(tag=k)) for k in FINAL]
    return api_pb2.Experiment(hparam_infos=infos, metric_infos=metrics)


def write_sweep_experiment(sweep: Path) -> Path | None:
    """The sweep's HParams experiment, once, in an event file at its root (TensorBoard reads the first experiment it
    finds, so the jobs write none: each job's session names its values). Rewritten on each run of the sweep."""
    import json

    from tensorboard.compat.proto import event_pb2
    from tensorboard.compat.proto.summary_pb2 import Summary, SummaryMetadata
    from tensorboard.plugins.hparams import plugin_data_pb2

    jobs = []
    for path in sorted(sweep.rglob("results.json")):
        try:
            res = json.loads(path.read_bytes())
            if res.get("status") in ("complete", "diverged"):
                jobs.append((job_hparams(res, path.parent), overrides_of(path.parent)))
        except (OSError, ValueError, KeyError, TypeError):
            continue
    if not jobs:
        return None
    for old in sweep.glob("events.out.tfevents.*.sweep.selpres"):
        old.unlink()
    data = plugin_data_pb2.HParamsPluginData(experiment=sweep_experiment(jobs), version=0)
    meta = SummaryMetadata(
        plugin_data=SummaryMetadata.PluginData(plugin_name=_HPARAMS_PLUGIN, content=data.SerializeToString())
    )
    summary = Summary(value=[Summary.Value(tag=_HPARAMS_TAGS[0], metadata=meta)])
    path = sweep / f"events.out.tfevents.{int(time.time()):010d}.{socket.gethostname()}.sweep.selpres"
    f = EventFile(path)
    f.write(event_pb2.Event(wall_time=time.time(), file_version="brain.Event:2").SerializeToString())
    f.write(event_pb2.Event(wall_time=time.time(), summary=summary).SerializeToString())
    f.close()
    return path


class SweepHParams(Callback):
    """Hydra callback: after a sweep, its HParams experiment at the sweep's root (:func:`write_sweep_experiment`)."""

    def on_multirun_end(self, config, **kwargs) -> None:
        from omegaconf import OmegaConf

        try:
            write_sweep_experiment(Path(str(OmegaConf.select(config, "hydra.sweep.dir"))))
        except OSError as e:  # the sweep's results are all written; only TensorBoard's column list is missing
            log.warning("TensorBoard's HParams experiment of the sweep not written: %s", e)


def close_job(tracker: Tracker, results: dict, folder: Path | None) -> None:
    """The end of a job's log: the final metrics at its cost, its hyperparameters, every final metric as text."""
    summary = results["summary"]
    final = {tag: summary[k]["mean"] for tag, k in FINAL.items() if k in summary and summary[k]["mean"] is not None}
    tracker.final(final, int(round(results.get("presentations_done") or 0)))
    floor_nm = {f"final/floor_{k}_nm_overall": v["nm"]["overall"] for k, v in (results.get("floor") or {}).items()}
    tracker.close(job_hparams(results, folder), {**{f"final/{k}": v["mean"] for k, v in summary.items()}, **floor_nm})
