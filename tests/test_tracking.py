"""TensorBoard: curves against epochs and presentations, replica aggregates, stages, hparams in the job folder."""

from __future__ import annotations

import math

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.plugins.hparams import plugin_data_pb2

from selpres.run.train import train

from conftest import cfg_of


def load(tb_dir) -> EventAccumulator:
    acc = EventAccumulator(str(tb_dir), size_guidance={"scalars": 0, "tensors": 0})
    acc.Reload()
    return acc


def test_curves_by_epoch_and_by_presentations(tmp_path):
    res = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=3", "eval.every=1"), tmp_path)
    acc = load(tmp_path)  # the job folder: TensorBoard names the run by it
    tags = set(acc.Tags()["scalars"])
    for metric in ("train_mse", "test10_rms_nm", "heldout_rms_nm"):
        for stat in ("mean", "min", "max"):
            assert {f"{metric}/{stat}/by_epoch", f"{metric}/{stat}/by_presentations"} <= tags
    assert {f"replicas/heldout_rms_nm/r{r:03d}/by_presentations" for r in range(3)} <= tags

    by_pres = acc.Scalars("heldout_rms_nm/mean/by_presentations")
    assert [e.step for e in by_pres] == [rec["presentations"] for rec in res["curves"]]  # starts at 0, no duplicates
    mean_last = sum(res["curves"][-1]["heldout_rms_nm"]) / 3
    assert abs(by_pres[-1].value - mean_last) < 1e-6  # float32 in the event file
    stages = acc.Scalars("schedule/stage/by_epoch")
    assert [int(e.value) for e in stages] == [1, 1, 2, 3, 4, 5, 5]

    # add_hparams wrote into the job's own folder (run_name="."), not a timestamped sub-folder
    assert [p for p in tmp_path.iterdir() if p.is_dir()] == []
    content = acc.PluginTagToContent("hparams")
    start = plugin_data_pb2.HParamsPluginData.FromString(content["_hparams_/session_start_info"]).session_start_info
    assert {"schedule", "topology", "seed", "lr", "momentum", "sizes", "epochs"} <= set(start.hparams)
    assert start.hparams["topology"].string_value == "6-13-2"
    assert start.hparams["sizes"].string_value == "[50, 100, 400, 800, 1002]"  # lists flattened to strings
    assert "_hparams_/experiment" not in content  # the sweep's, once at its root (test_the_sweeps_hparams_experiment)
    # the schedule in the parametric schedule's words, numbers as numbers (parallel coordinates place them)
    assert start.hparams["p"].number_value == 4 and start.hparams["n1"].number_value == 50
    assert start.hparams["sum N_i"].number_value == 6 and start.hparams["growth"].string_value == "paper"
    cost = 50 + 100 + 400 + 800 + 2 * 1002  # by hand: one epoch of each set, two of the last
    assert start.hparams["cost (presentations)"].number_value == res["presentations_done"] == cost

    # each final metric is one scalar at the job's cost: the mean over replicas of all held-out patterns, not the
    # last point of the 300-pattern curve
    for tag, key in (
        ("final/heldout_rms_nm", "heldout_rms_nm_overall"),
        ("final/heldout_nmse", "heldout_rms_nmse_overall"),
    ):
        (point,) = acc.Scalars(tag)
        assert point.step == cost and math.isclose(point.value, res["summary"][key]["mean"], rel_tol=1e-6)
    curves = [t for t in tags if not t.startswith("final/")]
    assert all(len(acc.Scalars(t)) > 1 for t in curves), [t for t in curves if len(acc.Scalars(t)) == 1]

    # Custom Scalars: one Margin chart per quantity (mean with its min-max band), against presentations and epochs
    from tensorboard.plugins.custom_scalar import layout_pb2

    (config,) = acc.Tensors("custom_scalars__config__")
    layout = layout_pb2.Layout.FromString(config.tensor_proto.string_val[0])
    margins = [c.margin.series[0] for cat in layout.category for c in cat.chart if c.HasField("margin")]
    assert {(m.value, m.lower, m.upper) for m in margins} == {
        (f"{q}/mean/by_{a}", f"{q}/min/by_{a}", f"{q}/max/by_{a}")
        for q in ("heldout_rms_nm", "test10_rms_nm", "train_mse")
        for a in ("presentations", "epoch")
    }
    assert all({m.value, m.lower, m.upper} <= tags for m in margins)  # every chart's tags are written
    assert acc.PluginTagToContent("text") == {"final": b""}
    (table,) = acc.Tensors("final")
    rows = dict(
        line.strip("|").replace(" ", "").split("|")
        for line in table.tensor_proto.string_val[0].decode().splitlines()[2:]
    )
    want = res["summary"]["heldout_rms_nm_overall"]["mean"]
    assert math.isclose(float(rows["final/heldout_rms_nm_overall"]), want, rel_tol=1e-5)
    assert len(rows) >= 20  # every final metric, per joint and overall


def test_event_files_are_what_tensorboards_record_writer_writes(tmp_path):
    """The C checksum gives TensorBoard's own masked CRC-32C on any bytes (its pure-Python stub), an
    EventFile holds byte-for-byte what TensorBoard's RecordWriter writes, and a job's event file reads back."""
    import io
    import os

    from tensorboard.compat.tensorflow_stub.pywrap_tensorflow import masked_crc32c as stub
    from tensorboard.summary.writer.record_writer import RecordWriter

    from selpres.run.tracking import EventFile, event_checksum

    crc, in_c = event_checksum()
    assert in_c and crc is not stub
    for n in (0, 1, 3, 8, 255, 4096, 40_000):
        data = os.urandom(n)
        assert crc(data) == stub(data), n
    assert crc(b"123456789") == stub(b"123456789")  # the CRC-32C check string

    records = [os.urandom(n) for n in (0, 5, 300, 70_000)]
    ours, theirs = EventFile(tmp_path / "ours"), RecordWriter(io.BytesIO())
    for r in records:
        ours.write(r)
        theirs.write(r)
    ours.close()
    assert (tmp_path / "ours").read_bytes() == theirs._writer.getvalue()

    train(cfg_of("schedule.epochs=[1,1,1,1,1]", "replicas=2"), tmp_path / "job")
    assert len(load(tmp_path / "job").Scalars("heldout_rms_nm/mean/by_presentations")) == 6  # read back


def test_the_text_summary_is_tensorboards():
    from tensorboard.plugins.text.summary_v2 import text_pb

    from selpres.run.tracking import metrics_table, text_summary

    table = metrics_table({"final/heldout_rms_nm_overall": 0.2123456789, "final/ü": 3})
    assert table.splitlines()[2:] == ["| final/heldout_rms_nm_overall | 0.212346 |", "| final/ü | 3 |"]
    assert text_summary("final", table).SerializeToString() == text_pb("final", table).SerializeToString()


def test_runs_are_named_by_the_folder_given_and_only_the_writers_own_files_are_replaced(tmp_path):
    """A Tracker given a job's own folder writes its event file there (TensorBoard names the run by that folder,
    its overrides), and a resumed job replaces only its own event file, nothing else in the folder."""
    from tensorboard.backend.event_processing.plugin_event_multiplexer import EventMultiplexer

    from selpres.run.tracking import Tracker

    rec = {"epoch": 0, "stage": 0, "size": 50, "presentations": 50, "train_mse": [0.5], "heldout_rms_nm": [0.3]}
    sweep = tmp_path / "sweep"
    for name in ("seed=0", "seed=1"):
        job = sweep / name
        job.mkdir(parents=True)
        (job / "notes.txt").write_text("the user's")
        for _ in range(2):  # the second: a resumed job rebuilding its log
            t = Tracker(job)
            t.replay([rec, {**rec, "epoch": 1, "presentations": 100}])
            t.close({"seed": 0}, {"final/heldout_rms_nm_overall": 0.3})
        assert len(list(job.glob("events.out.tfevents.*"))) == 1 and (job / "notes.txt").read_text() == "the user's"
    mux = EventMultiplexer().AddRunsFromDirectory(str(sweep))
    mux.Reload()
    assert sorted(mux.Runs()) == ["seed=0", "seed=1"]  # no "/tb" suffix
    assert "heldout_rms_nm/mean/by_epoch" in mux.PluginRunToTagToContent("scalars")["seed=0"]


def test_hparams_summaries_are_torchs():
    """What the job writes for TensorBoard's HParams plugin equals torch's add_hparams summaries."""
    from torch.utils.tensorboard.summary import hparams

    from selpres.run.tracking import hparams_summaries

    hp = {"schedule": "selective", "replicas": 30, "lr": 0.15, "overwrite": False, "note": None, "ü": "δ"}
    metrics = {"final/heldout_rms_nm_overall": 0.21, "final/test10_rms_nm_overall": 0.3}
    ours = [s.SerializeToString() for s in hparams_summaries(hp, metrics)]
    assert ours == [s.SerializeToString() for s in hparams(hp, metrics)]


def test_hand_encoded_events_are_what_protobuf_serialises():
    """ScalarEvents' bytes equal protobuf's own serialisation of the same Event, for tags and values that
    exercise the encoding's corners: multi-byte lengths, step 0 (left out) and 2**40, negative zero, NaN,
    infinities, a double beyond float32's range, non-ASCII tags."""
    import random

    from tensorboard.compat.proto import event_pb2, summary_pb2

    from selpres.run.tracking import ScalarEvents

    rng = random.Random(7)
    enc = ScalarEvents()
    values = [0.0, -0.0, 1.5, float("nan"), float("inf"), -float("inf"), 1e300, -1e-300, 3.4e38, 123456.789]
    tags = ["a", "train_mse/mean/by_epoch", "ü/δ" * 9, "x" * 200, "replicas/heldout_rms_nm/r007/by_presentations"]
    for step in (0, 1, 127, 128, 300, 2**40):
        for n in (1, 2, 11, 40):
            scalars = [(rng.choice(tags), rng.choice(values)) for _ in range(n)]
            wall = rng.choice([0.0, 1.7e9 + rng.random()])
            summary = summary_pb2.Summary(value=[summary_pb2.Summary.Value(tag=t, simple_value=v) for t, v in scalars])
            want = event_pb2.Event(wall_time=wall, step=step, summary=summary).SerializeToString()
            assert enc.encode(scalars, step, wall) == want, (step, n, wall)


def test_the_sweeps_hparams_experiment(tmp_path):
    """After a sweep, one experiment at its root: every job's hyperparameters (numbers as numbers, text with its
    values), the sweep's own columns marked as differing (TensorBoard shows those first), the final metrics declared;
    TensorBoard's own reader lists every job as a session with its values."""
    from tensorboard.backend.event_processing.plugin_event_multiplexer import EventMultiplexer
    from tensorboard.plugins.hparams import api_pb2

    from selpres.run.hparams import write_sweep_experiment

    for p in (1, 2):
        job = tmp_path / f"schedule.p={p}"
        train(cfg_of("schedule=stages", f"schedule.p={p}", "schedule.total_epochs=4"), job)
        (job / ".hydra").mkdir()
        (job / ".hydra" / "overrides.yaml").write_text(f"- schedule=stages\n- schedule.p={p}\n")
    write_sweep_experiment(tmp_path)
    mux = EventMultiplexer().AddRunsFromDirectory(str(tmp_path))
    mux.Reload()
    content = mux.PluginRunToTagToContent("hparams")
    assert [run for run, tags in content.items() if "_hparams_/experiment" in tags] == ["."]
    experiment = plugin_data_pb2.HParamsPluginData.FromString(content["."]["_hparams_/experiment"]).experiment
    finals = ["final/heldout_rms_nm", "final/heldout_nmse", "final/test10_rms_nm"]
    assert [m.name.tag for m in experiment.metric_infos] == finals  # the final numbers, not a curve's last point
    info = {h.name: h for h in experiment.hparam_infos}
    number = api_pb2.DataType.Value("DATA_TYPE_FLOAT64")
    assert info["p"].type == info["schedule.p"].type == info["cost (presentations)"].type == number
    assert {k for k, h in info.items() if h.differs} == {"p", "schedule.p", "cost (presentations)"}  # the sweep
    assert [v.string_value for v in info["growth"].domain_discrete.values] == ["geometric"]
    sessions = {
        run: plugin_data_pb2.HParamsPluginData.FromString(tags["_hparams_/session_start_info"]).session_start_info
        for run, tags in content.items()
        if "_hparams_/session_start_info" in tags
    }
    assert {run: s.hparams["p"].number_value for run, s in sessions.items()} == {"schedule.p=1": 1, "schedule.p=2": 2}
