"""Progress on long work: a sweep's count of jobs done, and a job's place within its stage.

**A sweep** (:class:`SweepProgress`, a Hydra callback in ``configs/train.yaml``): as each job ends, one line on the
sweep's console, ``sweep: 5/8 jobs done (1 failed), 1 min 12 s elapsed, about 43 s left``. The sweep's process
counts its jobs before launching them (the sweeper's own product of values; an Optuna sweep's ``n_trials``) and
names a file its workers share in their inherited environment; each worker's job appends one line there when it
ends (jobs of ``hydra/launcher=local2`` end in other processes), so the count is right however many run at once.
The estimate is the elapsed time per job done so far times the jobs left: a re-run that finds jobs finished counts
them as done at once, so early estimates are low.

**A job on a terminal** (:class:`EpochLine`, ``selpres.run.train.train``'s ``on_epoch``): once a job has run
longer than :data:`QUIET_SECONDS`, one line rewritten in place at most every :data:`REDRAW_SECONDS`: its stage, the
epoch, the presentations done of the plan's and an estimate of the time left (from the presentations, which is
what the time of an epoch grows with). Cleared at each stage end, where the usual stage line follows. Only for a
single run whose error stream is a terminal: a log file or a pipe gets only the usual lines, and a sweep's workers
share one terminal, where their lines would overwrite each other (the sweep's count is their progress).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

ENV = "SELPRES_SWEEP_PROGRESS"  # the file a sweep's jobs append to: {"total": N, "start": t} then one line a job
QUIET_SECONDS = 3.0  # a job shorter than this prints nothing more than its usual lines
REDRAW_SECONDS = 0.5


def duration(seconds: float) -> str:
    """ "12 s", "3 min 05 s", "1 h 02 min": as a person reads a wait."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def sweep_size(config: DictConfig) -> int | None:
    """How many jobs the sweep of ``config`` launches: an Optuna sweep's ``n_trials``, else the basic sweeper's product
    of values (its ``params``, each replaced by the command line's value of the same key; partners=on adds its own
    when it knows them); None where it cannot be told."""
    trials = OmegaConf.select(config, "hydra.sweeper.n_trials")  # an Optuna sweep (experiment=search)
    if trials is not None:
        return int(trials) if isinstance(trials, int) else None
    try:
        from hydra._internal.config_loader_impl import ConfigLoaderImpl
        from hydra._internal.utils import create_config_search_path
        from hydra.core.override_parser.overrides_parser import OverridesParser

        from selpres.run.config import CONFIG_DIR

        params = OmegaConf.select(config, "hydra.sweeper.params") or {}
        given = [f"{k}={v}" for k, v in params.items()] + list(config.hydra.overrides.task)
        loader = ConfigLoaderImpl(config_search_path=create_config_search_path(str(CONFIG_DIR)))
        counts: dict[str, int] = {}  # by key, the later one winning, as Hydra's basic sweeper merges them
        for o in OverridesParser.create(config_loader=loader).parse_overrides(given):
            counts[o.get_key_element()] = len(list(o.sweep_string_iterator())) if o.is_sweep_override() else 1
        return math.prod(counts.values())
    except Exception:  # a sweeper or syntax this count does not know: the lines say "k jobs done"
        return None


class SweepProgress(Callback):
    """Hydra callback: one line per job end with the count of jobs done, the elapsed time and an estimate of the
    rest (see the module's docstring)."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        folder = Path(str(OmegaConf.select(config, "hydra.sweep.dir")))
        try:
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / f".progress-{os.getpid()}.jsonl"
            path.write_text(json.dumps({"total": sweep_size(config), "start": time.time()}) + "\n")
        except OSError:
            return  # a sweep folder that cannot be written fails on its own; the count is not worth a second line
        os.environ[ENV] = str(path.resolve())

    def on_job_end(self, config: DictConfig, job_return: Any, **kwargs: Any) -> None:
        path = os.environ.get(ENV)
        if not path:
            return
        status = getattr(getattr(job_return, "status", None), "name", "UNKNOWN")
        try:
            with open(path, "a") as f:  # one short appended line: whole even when two workers end at once
                f.write(json.dumps({"status": status, "end": time.time()}) + "\n")
            print(sweep_line(Path(path)), file=sys.stderr, flush=True)
        except (OSError, ValueError):
            pass

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        path = os.environ.pop(ENV, None)
        if path:
            Path(path).unlink(missing_ok=True)


def sweep_line(path: Path, now: float | None = None) -> str:
    """The progress line from a sweep's progress file."""
    head, *lines = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    ends = [e for e in lines if "status" in e]
    done, failed = len(ends), sum(e["status"] == "FAILED" for e in ends)
    total = head.get("total")
    total = total + sum(e.get("more", 0) for e in lines) if total else None  # jobs a sweeper adds (partners)
    elapsed = (now or time.time()) - head["start"]
    count = f"{done}/{total}" if total else f"{done}"
    text = f"sweep: {count} jobs done" + (f" ({failed} failed)" if failed else "") + f", {duration(elapsed)} elapsed"
    if total and done < total:
        text += f", about {duration(elapsed / done * (total - done))} left"
    return text


class EpochLine:
    """``on_epoch(record, problem)`` for a single run on a terminal: the line described in the module's docstring."""

    def __init__(self, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.monotonic()
        self.shown = False
        self.last = 0.0
        self.start_presentations: int | None = None

    @classmethod
    def for_run(cls, multirun: bool) -> EpochLine | None:
        """The line for a single run whose error stream is a terminal; None otherwise."""
        stream = sys.stderr
        return cls(stream) if not multirun and hasattr(stream, "isatty") and stream.isatty() else None

    def __call__(self, rec: dict, prob: Any) -> None:
        now = time.monotonic()
        done = rec["presentations"]
        if self.start_presentations is None:  # a resumed job: its rate from what this process did
            self.start_presentations = done - prob.plan[rec["epoch"]].presentations
        if rec["epoch"] in prob.stage_ends or rec["epoch"] == len(prob.plan) - 1:
            self.clear()
            return
        if now - self.t0 < QUIET_SECONDS or now - self.last < REDRAW_SECONDS:
            return
        self.last = now
        total, stages = prob.schedule.presentations, len(prob.schedule.stages)
        rate = (done - self.start_presentations) / (now - self.t0)
        left = f", about {duration((total - done) / rate)} left" if rate > 0 and total > done else ""
        text = (
            f"stage {rec['stage'] + 1}/{stages}  n_i={rec['size']:,}  epoch {rec['epoch'] + 1:,}/{len(prob.plan):,}  "
            f"presentations {done:,}/{total:,} ({100 * done / max(1, total):.0f} %){left}"
        )
        self.stream.write("\r\033[K" + text)
        self.stream.flush()
        self.shown = True

    def clear(self) -> None:
        if self.shown:
            self.stream.write("\r\033[K")
            self.stream.flush()
            self.shown = False
