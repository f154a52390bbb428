"""TensorBoard logging of a job's history: every curve twice, against epochs and against presentations.

Curves against cumulative presentations are the fair axis: a selective and a conventional run are
compared at equal cost there. The log is a pure function of the history records, so a resumed run
rebuilds it from the checkpoint's history instead of appending duplicates.

What a sweep is compared by (its HParams, the final metrics at each job's cost) is :mod:`selpres.run.hparams`'s;
the Custom Scalars tab (:func:`layout_summary`, once per file) has one chart per quantity against presentations and
against epochs: the mean over replicas with its min–max band (a Margin chart), every run in one chart.
"""

from __future__ import annotations

import functools
import logging
import math
import os
import socket
import struct
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from selpres.storage import flatten, naming

log = logging.getLogger("selpres")

METRICS = ("train_mse", "test10_rms_nm", "heldout_rms_nm")


@functools.lru_cache(maxsize=1)
def event_checksum() -> tuple[Callable[[bytes], int], bool]:
    """TFRecord's masked CRC-32C, and whether it runs in C (google-crc32c) rather than TensorBoard's pure
    Python (its tensorflow stub: 3 ms for the 30 KB event of a 1000-replica curve point, 20 us for a small
    one, and 0.1 s to import). The two give the same checksums (tests/test_tracking.py)."""
    try:
        import google_crc32c

        if getattr(google_crc32c, "implementation", "") == "c":
            crc = google_crc32c.value

            def masked_crc32c(data: bytes) -> int:  # TensorBoard's masking of the CRC-32C (TFRecord format)
                x = crc(data)
                return (((x >> 15) | (x << 17)) + 0xA282EAD8) & 0xFFFFFFFF

            return masked_crc32c, True
    except ImportError:
        pass
    from tensorboard.compat.tensorflow_stub.pywrap_tensorflow import masked_crc32c

    return masked_crc32c, False


class EventFile:
    """An event file in TensorBoard's record format (TFRecord: length, its checksum, data, its checksum), as
    tensorboard's RecordWriter frames it; written here because importing that writer took 0.1 s of every job."""

    def __init__(self, path: Path):
        self.path = path
        self._file = open(path, "wb")
        self._crc = event_checksum()[0]

    def write(self, data: bytes) -> None:
        header = struct.pack("<Q", len(data))
        with naming(self.path):
            self._file.write(header + struct.pack("<I", self._crc(header)) + data + struct.pack("<I", self._crc(data)))

    def flush(self) -> None:
        with naming(self.path):
            self._file.flush()

    def close(self) -> None:
        with naming(self.path):  # the buffer's last bytes are written here: a full disk fails here too
            self._file.close()


def hparams_and_metrics(hparams: dict, metrics: dict) -> tuple[dict, dict]:
    """The flat values TensorBoard's HParams plugin takes: hyperparameters as int/float/str/bool (others as text),
    the finite numeric metrics."""
    hp = {k: (v if isinstance(v, (int, float, str, bool)) else str(v)) for k, v in flatten(hparams, "/").items()}
    mt = {k: v for k, v in flatten(metrics, "/").items() if isinstance(v, (int, float)) and math.isfinite(v)}
    return hp, mt


_HPARAMS_PLUGIN = "hparams"  # tensorboard.plugins.hparams.metadata's names (importing it took 0.1 s)
_HPARAMS_TAGS = ("_hparams_/experiment", "_hparams_/session_start_info", "_hparams_/session_end_info")


def hparams_summaries(hparams: dict, metrics: dict) -> list:
    """The three summaries (experiment, session start, session end) that TensorBoard's HParams plugin reads,
    as ``torch.utils.tensorboard.summary.hparams(hparams, metrics)`` builds them (tested equal), for values
    that are int, float, str or bool; without importing torch's tensorboard module (0.16 s)."""
    from tensorboard.compat.proto.summary_pb2 import Summary, SummaryMetadata
    from tensorboard.plugins.hparams import api_pb2, plugin_data_pb2

    start = plugin_data_pb2.SessionStartInfo()
    infos = []
    for k, v in hparams.items():
        if v is None:
            continue
        if isinstance(v, (int, float)):  # bools too, as torch files them: a number
            start.hparams[k].number_value = v
            kind = "DATA_TYPE_FLOAT64"
        elif isinstance(v, str):
            start.hparams[k].string_value = v
            kind = "DATA_TYPE_STRING"
        else:
            raise ValueError(f"hparam {k}={v!r}: expected int, float, str or bool")
        infos.append(api_pb2.HParamInfo(name=k, type=api_pb2.DataType.Value(kind)))
    experiment = api_pb2.Experiment(
        hparam_infos=infos, metric_infos=[api_pb2.MetricInfo(name=api_pb2.MetricName(tag=k)) for k in metrics]
    )
    end = plugin_data_pb2.SessionEndInfo(status=api_pb2.Status.Value("STATUS_SUCCESS"))
    contents = (
        plugin_data_pb2.HParamsPluginData(experiment=experiment, version=0),
        plugin_data_pb2.HParamsPluginData(session_start_info=start, version=0),
        plugin_data_pb2.HParamsPluginData(session_end_info=end, version=0),
    )
    return [
        Summary(
            value=[
                Summary.Value(
                    tag=tag,
                    metadata=SummaryMetadata(
                        plugin_data=SummaryMetadata.PluginData(
                            plugin_name=_HPARAMS_PLUGIN, content=content.SerializeToString()
                        )
                    ),
                )
            ]
        )
        for tag, content in zip(_HPARAMS_TAGS, contents)
    ]


def text_summary(tag: str, markdown: str):
    """A Summary that TensorBoard's Text plugin shows (a string tensor, plugin "text"), as
    ``tensorboard.plugins.text.summary_v2.text_pb(tag, markdown)`` builds it (tested equal), without importing that."""
    from tensorboard.compat.proto import tensor_pb2, tensor_shape_pb2, types_pb2
    from tensorboard.compat.proto.summary_pb2 import Summary, SummaryMetadata

    tensor = tensor_pb2.TensorProto(
        dtype=types_pb2.DT_STRING, string_val=[markdown.encode()], tensor_shape=tensor_shape_pb2.TensorShapeProto()
    )
    meta = SummaryMetadata(plugin_data=SummaryMetadata.PluginData(plugin_name="text"))
    return Summary(value=[Summary.Value(tag=tag, metadata=meta, tensor=tensor)])


def metrics_table(metrics: dict) -> str:
    """The final metrics as a two-column Markdown table (what the Text tab renders)."""
    rows = [f"| {k} | {v:.6g} |" for k, v in metrics.items()]
    return "\n".join(["| final metric | value |", "|---|---|", *rows])


CHARTS = (  # (title, the curve's tag stem): one Margin chart each, against presentations and against epochs
    ("held-out RMS (Nm), first eval.heldout_curve patterns", "heldout_rms_nm"),
    ("test-10 RMS (Nm)", "test10_rms_nm"),
    ("training MSE (scaled)", "train_mse"),
)


def layout_summary():
    """TensorBoard's Custom Scalars layout (as ``torch.utils.tensorboard.summary.custom_scalars`` builds it): per
    quantity one Margin chart, the mean over replicas with its min–max band, against presentations (the cost axis
    on which runs of different cost line up) and against epochs; the stage and training-set size as lines."""
    from tensorboard.compat.proto import tensor_pb2, tensor_shape_pb2, types_pb2
    from tensorboard.compat.proto.summary_pb2 import Summary, SummaryMetadata
    from tensorboard.plugins.custom_scalar import layout_pb2

    def margin(title: str, stem: str, axis: str):
        tags = [f"{stem}/{k}/by_{axis}" for k in ("mean", "min", "max")]
        series = layout_pb2.MarginChartContent.Series(value=tags[0], lower=tags[1], upper=tags[2])
        return layout_pb2.Chart(title=title, margin=layout_pb2.MarginChartContent(series=[series]))

    def lines(title: str, pattern: str):
        return layout_pb2.Chart(title=title, multiline=layout_pb2.MultilineChartContent(tag=[pattern]))

    categories = [
        layout_pb2.Category(
            title=f"against {axis} (mean over replicas, band: min to max)",
            chart=[margin(f"{title} by {axis}", stem, axis) for title, stem in CHARTS]
            + [lines(f"stage by {axis}", f"^schedule/stage/by_{axis}$")],
        )
        for axis in ("presentations", "epoch")
    ]
    tensor = tensor_pb2.TensorProto(
        dtype=types_pb2.DT_STRING,
        string_val=[layout_pb2.Layout(category=categories).SerializeToString()],
        tensor_shape=tensor_shape_pb2.TensorShapeProto(),
    )
    meta = SummaryMetadata(plugin_data=SummaryMetadata.PluginData(plugin_name="custom_scalars"))
    return Summary(value=[Summary.Value(tag="custom_scalars__config__", tensor=tensor, metadata=meta)])


def _varint(n: int) -> bytes:
    """A non-negative int in protobuf's base-128 varint encoding."""
    out = bytearray()
    while n > 0x7F:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


class ScalarEvents:
    """Events of ``simple_value`` scalars in protobuf's wire format, built from bytes cached per tag.

    Building them as protobuf objects (an Event, a Summary, a Value per scalar) cost ~20 us an event at R = 1
    and ~0.4 ms for the 1000-replica held-out curve; here an event is a join of cached bytes. The result is
    byte-for-byte ``Event(wall_time, step, summary=Summary(value=[Value(tag, simple_value)])).SerializeToString()``
    (tests/test_tracking.py), so TensorBoard reads it as it reads any event."""

    def __init__(self):
        self._values: dict[str, bytes] = {}  # tag -> the Value's bytes up to its float

    def _value_head(self, tag: str) -> bytes:
        head = self._values.get(tag)
        if head is None:
            t = tag.encode()
            value = b"\x0a" + _varint(len(t)) + t + b"\x15"  # Value.tag (1, string); simple_value (2, float32)
            head = self._values[tag] = b"\x0a" + _varint(len(value) + 4) + value  # Summary.value (1, repeated)
        return head

    def encode(self, scalars: list[tuple[str, float]], step: int, wall_time: float) -> bytes:
        with np.errstate(over="ignore"):  # beyond float32's range: inf, as protobuf's float field stores it
            f32 = np.array([v for _, v in scalars], dtype=np.float32).tobytes()
        summary = b"".join(self._value_head(tag) + f32[4 * i : 4 * i + 4] for i, (tag, _) in enumerate(scalars))
        event = b"\x09" + struct.pack("<d", wall_time) if wall_time else b""  # Event.wall_time (1, double)
        if step:  # proto3 leaves a zero out
            event += b"\x10" + _varint(step if step > 0 else step + (1 << 64))  # Event.step (2, int64)
        return event + b"\x2a" + _varint(len(summary)) + summary  # Event.summary (5)


class Tracker:
    """TensorBoard event files written in the loop's own thread.

    Kept by measurement (``python -m selpres_bench.tracking``, 2026-12-01, load 0.6, 3 rounds, conventional
    6-13-2): against the same scalars and hparams through ``torch.utils.tensorboard.SummaryWriter``, the R = 1
    job's ``train()`` took 0.31 s instead of 0.60 s (x1.79-2.26) and its whole process 2.42 s instead of 2.85 s;
    the R = 1000 job's ``train()`` 9.9 s instead of 12.8 s (x1.29-1.38). The byte-for-byte tests against
    TensorBoard's own writer are in tests/test_tracking.py. (Measured when the final metrics were one scalar event at
    close; they are now one text event there, the per-epoch writing unchanged but for noting which mean curves
    exist (a list check of ~11 tags): not re-measured, 2026-12-03's machine
    was too loaded to time it, x0.82-2.74 between rounds.)

    Each record's scalars go into one event per step (epoch, presentations), appended in TensorBoard's
    record format (tensorboard's RecordWriter), flushed at checkpoints and at the end. torch's
    SummaryWriter would hand every event to a writer thread, which then competes with the loop for the GIL
    whenever a kernel call returns: an R = 1 job's updates took a quarter longer with it.
    """

    def __init__(self, logdir: Path, enabled: bool = True, per_replica: bool = True):
        """``per_replica`` adds each replica's held-out curve (at the points it is scored) to the aggregates."""
        self.enabled = enabled
        self.per_replica = per_replica
        self.logdir = Path(logdir)
        self.writer = None  # the EventFile, while open
        self._curve_tags: list[str] = []  # the by-epoch curves written, whose last values HParams shows
        self._final_tags: list[str] = []  # the final metrics written (:meth:`final`): HParams' metrics instead
        if enabled:
            from tensorboard.compat.proto import event_pb2

            if not event_checksum()[1]:
                log.warning("TensorBoard checksums its events in pure Python (google-crc32c missing): slower logging")
            self.logdir.mkdir(parents=True, exist_ok=True)
            for old in self.logdir.glob("events.out.tfevents.*.selpres"):  # rebuilt from history on resume
                old.unlink()  # (only this writer's own files: a job folder holds others)
            self._event, self._scalars = event_pb2.Event, ScalarEvents()
            name = f"events.out.tfevents.{int(time.time()):010d}.{socket.gethostname()}.{os.getpid()}.selpres"
            self.writer = EventFile(self.logdir / name)  # closed in close()
            self._append(self._event(wall_time=time.time(), file_version="brain.Event:2"))
            self._append(self._event(wall_time=time.time(), summary=layout_summary()))

    def _append(self, event) -> None:
        self.writer.write(event.SerializeToString())

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
        self._curve_tags += [t for t, _ in by_epoch if t.endswith("/mean/by_epoch") and t not in self._curve_tags]

    def _write(self, scalars: list[tuple[str, float]], step: int) -> None:
        """One event holding every scalar of a step, each a simple_value as ``add_scalar`` writes it."""
        self.writer.write(self._scalars.encode(scalars, int(step), time.time()))

    def flush(self) -> None:
        """Hand what is buffered to the file (the loop calls it at checkpoints; ``close`` at the end)."""
        if self.writer is not None:
            self.writer.flush()

    def replay(self, history: list[dict]) -> None:
        for rec in history:
            self.log_epoch(rec)

    def final(self, scalars: dict, step: int) -> None:
        """The job's final metrics (:data:`FINAL`), one scalar each at ``step`` (the job's cost): the metrics the
        HParams tab declares, and in the Time Series tab one point per run at its cost."""
        finite = [(k, v) for k, v in scalars.items() if v is not None and math.isfinite(v)]
        if self.writer is None or not finite:
            return
        self._write(finite, step)
        self._final_tags += [k for k, _ in finite]

    def close(self, hparams: dict, metrics: dict) -> None:
        """The hyperparameters for TensorBoard's HParams plugin (torch's ``add_hparams`` summaries, into this same
        file), its metrics the final ones written by :meth:`final` (else the mean curves, whose last value it
        shows), and every final metric in a Markdown table (Text tab, tag ``final``); then the file is closed."""
        if self.writer is None:
            return
        hp, mt = hparams_and_metrics(hparams, metrics)
        curves = {tag: None for tag in self._final_tags or self._curve_tags}
        # the session's start and end; the experiment (which columns and metrics) is the sweep's, written once at its
        # root after it (write_sweep_experiment), else TensorBoard infers it from the sessions
        for summary in hparams_summaries(hp, curves)[1:]:
            self._append(self._event(wall_time=time.time(), summary=summary))
        if mt:
            self._append(self._event(wall_time=time.time(), summary=text_summary("final", metrics_table(mt))))
        self.writer.close()
        self.writer = None
