"""TensorBoard logging of a job's history: every curve twice, against epochs and against presentations.

Curves against cumulative presentations are the fair axis: a selective and a conventional run are
compared at equal cost there. The log is a pure function of the history records, so a resumed run
rebuilds it from the checkpoint's history instead of appending duplicates.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

from selpres.storage import flatten

METRICS = ("train_mse", "test10_rms_nm", "heldout_rms_nm")


class Tracker:
    def __init__(self, logdir: Path, enabled: bool = True, per_replica: bool = True):
        """``per_replica`` adds each replica's held-out curve (at the points it is scored) to the aggregates."""
        self.enabled = enabled
        self.per_replica = per_replica
        self.logdir = Path(logdir)
        self.writer = None
        if enabled:
            from tensorboard.compat.proto.summary_pb2 import Summary
            from torch.utils.tensorboard import SummaryWriter

            self._summary = Summary

            if self.logdir.exists():  # rebuilt from history on resume
                shutil.rmtree(self.logdir)
            self.writer = SummaryWriter(str(self.logdir), max_queue=10_000, flush_secs=30)

    def log_epoch(self, rec: dict) -> None:
        if self.writer is None:
            return
        by_epoch, by_pres = [], []  # (tag, value) at step epoch + 1, and at step presentations
        for metric in METRICS:
            vals = rec.get(metric)
            if vals is None:
                continue
            finite = [v for v in vals if v is not None and math.isfinite(v)]
            if not finite:
                continue
            stats = {"mean": sum(finite) / len(finite), "min": min(finite), "max": max(finite)}
            for name, v in stats.items():
                by_epoch.append((f"{metric}/{name}/by_epoch", v))
                by_pres.append((f"{metric}/{name}/by_presentations", v))
            if self.per_replica and len(vals) > 1 and metric == "heldout_rms_nm":  # against cost only
                by_pres += [
                    (f"replicas/{metric}/r{r:03d}/by_presentations", v)
                    for r, v in enumerate(vals)
                    if v is not None and math.isfinite(v)
                ]
        by_epoch += [
            ("schedule/stage/by_epoch", rec["stage"] + 1),
            ("schedule/training_set_size/by_epoch", rec["size"]),
        ]
        by_pres.append(("schedule/stage/by_presentations", rec["stage"] + 1))
        self._write(by_epoch, rec["epoch"] + 1)
        self._write(by_pres, rec["presentations"])

    def _write(self, scalars: list[tuple[str, float]], step: int) -> None:
        """One event holding every scalar of a step: what ``add_scalar`` writes (a simple_value per tag),
        without an event, a proto and a queue put per scalar (~20 us each: 0.7 s of a 1000-replica job).
        The writer has no public call for several scalars at once, hence its file writer."""
        S = self._summary
        summary = S(value=[S.Value(tag=tag, simple_value=float(v)) for tag, v in scalars])
        self.writer._get_file_writer().add_summary(summary, step)

    def replay(self, history: list[dict]) -> None:
        for rec in history:
            self.log_epoch(rec)

    def close(self, hparams: dict, metrics: dict) -> None:
        if self.writer is None:
            return
        hp = {k: (v if isinstance(v, (int, float, str, bool)) else str(v)) for k, v in flatten(hparams, "/").items()}
        mt = {k: v for k, v in flatten(metrics, "/").items() if isinstance(v, (int, float)) and math.isfinite(v)}
        self.writer.add_hparams(hp, mt, run_name=".")
        self.writer.close()
