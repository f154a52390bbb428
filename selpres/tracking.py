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
            from torch.utils.tensorboard import SummaryWriter

            if self.logdir.exists():  # rebuilt from history on resume
                shutil.rmtree(self.logdir)
            self.writer = SummaryWriter(str(self.logdir), max_queue=10_000, flush_secs=30)

    def log_epoch(self, rec: dict) -> None:
        if self.writer is None:
            return
        w = self.writer
        for metric in METRICS:
            vals = rec.get(metric)
            if vals is None:
                continue
            finite = [v for v in vals if v is not None and math.isfinite(v)]
            if not finite:
                continue
            stats = {"mean": sum(finite) / len(finite), "min": min(finite), "max": max(finite)}
            for axis, step in (("epoch", rec["epoch"] + 1), ("presentations", rec["presentations"])):
                for name, v in stats.items():
                    w.add_scalar(f"{metric}/{name}/by_{axis}", v, step)
            if self.per_replica and len(vals) > 1 and metric == "heldout_rms_nm":  # against cost only
                for r, v in enumerate(vals):
                    if v is not None and math.isfinite(v):
                        w.add_scalar(f"replicas/{metric}/r{r:03d}/by_presentations", v, rec["presentations"])
        w.add_scalar("schedule/stage/by_epoch", rec["stage"] + 1, rec["epoch"] + 1)
        w.add_scalar("schedule/stage/by_presentations", rec["stage"] + 1, rec["presentations"])
        w.add_scalar("schedule/training_set_size/by_epoch", rec["size"], rec["epoch"] + 1)

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
