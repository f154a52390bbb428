"""The user's own data (data=file): CSV and .npz tables, the seeded held-out split, training on a
SARCOS-shaped file with every schedule, order and optimizer, and errors that name the file, column and row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from selpres.data.file import DataFileError, load_columns
from selpres.data.task import load_task
from selpres.errors import ConfigError
from selpres.run.specs import task_specs

from conftest import CONFIGS, cfg_of, run_python

ROOT = Path(__file__).resolve().parents[1]
INPUTS = [f"{p}{i}" for p in ("q", "dq", "ddq") for i in range(1, 8)]  # SARCOS: 7 joints, 21 inputs
OUTPUTS = [f"tau{i}" for i in range(1, 8)]


def sarcos_like(rows: int, seed: int = 0) -> np.ndarray:
    """A table shaped like the SARCOS inverse-dynamics set: 21 inputs, 7 smooth targets of them."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, (rows, 21))
    W = rng.normal(size=(21, 7))
    return np.hstack([X, np.tanh(X @ W / 4) * 20 + np.sin(X[:, :7]) * 3])


def write_csv(path: Path, table: np.ndarray, names: list[str], comments: str = "") -> Path:
    np.savetxt(path, table, delimiter=",", header=comments + ",".join(names), comments="", fmt="%.17g")
    return path


@pytest.fixture(scope="module")
def sarcos(tmp_path_factory) -> Path:
    return write_csv(tmp_path_factory.mktemp("sarcos") / "sarcos.csv", sarcos_like(600), INPUTS + OUTPUTS)


def file_cfg(path: Path, *overrides: str, inputs=INPUTS, outputs=OUTPUTS):
    width = f"{len(inputs)}-10-{len(outputs)}"
    return cfg_of(
        "data=file",
        f"data.path={path}",
        f"data.inputs=[{','.join(inputs)}]",
        f"data.outputs=[{','.join(outputs)}]",
        f"topology.layers={width}",
        "data.heldout=0.2",
        *overrides,
    )


def test_split_by_seed_and_test_patterns_from_the_heldout_rows(sarcos):
    cfg = file_cfg(sarcos)
    task = load_task(*task_specs(cfg))
    table = torch.from_numpy(np.loadtxt(sarcos, delimiter=",", skiprows=1))
    assert len(task.tests.heldout) == 120 and task.n == 480  # data.heldout: 0.2 of 600 rows
    both = torch.cat((task.exemplar.X, task.tests.heldout.X))
    assert torch.equal(both[both[:, 0].argsort()], table[table[:, 0].argsort(), :21])  # a partition of the rows
    ex_rows = task.exemplar.X[:, 0]
    assert torch.all(ex_rows[1:] != ex_rows[:-1])
    positions = [int((table[:, 0] == v).nonzero()) for v in ex_rows]
    assert positions == sorted(positions)  # the exemplar set keeps the file's order
    X10 = task.tests.test10.X
    assert all(torch.isin(X10[:5, 0], task.exemplar.X[:, 0])) and all(
        torch.isin(X10[5:, 0], task.tests.heldout.X[:, 0])
    )
    assert task.input_names == tuple(INPUTS) and task.output_names == tuple(OUTPUTS)
    assert task.info["kind"] == "file" and len(task.info["sha256"]) == 64
    other = file_cfg(sarcos, "data.test_seed=1")
    assert not torch.equal(load_task(*task_specs(other)).tests.heldout.X, task.tests.heldout.X)


def test_npz_columns_and_table_read_as_the_csv(sarcos, tmp_path):
    table = np.loadtxt(sarcos, delimiter=",", skiprows=1)
    np.savez(tmp_path / "cols.npz", **{n: table[:, i] for i, n in enumerate(INPUTS + OUTPUTS)})
    np.savez(tmp_path / "table.npz", table=table, columns=np.array(INPUTS + OUTPUTS))
    want = load_columns(sarcos, ["tau3", "q1"])
    for name in ("cols.npz", "table.npz"):
        assert torch.equal(load_columns(tmp_path / name, ["tau3", "q1"]), want)
    cfg = file_cfg(tmp_path / "cols.npz")
    a, b = load_task(*task_specs(cfg)), load_task(*task_specs(file_cfg(sarcos)))
    assert torch.equal(a.exemplar.X, b.exemplar.X) and torch.equal(a.tests.heldout.Y, b.tests.heldout.Y)


def test_exported_csv_loads_as_user_data(tmp_path):
    """selpres-export's own CSV (its '#' lines skipped) trains as data=file."""
    from selpres.run.export import compose_data_config, export_data

    robot, data = compose_data_config(["data.heldout=50"])
    export_data(tmp_path / "ex", robot, data)
    names = ["theta1", "dtheta1", "ddtheta1", "theta2", "dtheta2", "ddtheta2"]
    cfg = file_cfg(tmp_path / "ex_exemplar.csv", inputs=names, outputs=["tau1", "tau2"])
    task = load_task(*task_specs(cfg))
    assert task.n + len(task.tests.heldout) == 1002


def _schedules() -> list[str]:
    return sorted(p.stem for p in (CONFIGS / "schedule").glob("*.yaml"))


@pytest.mark.parametrize(
    "variant",
    [
        f"schedule={s}" if s == "selective" else pytest.param(f"schedule={s}", marks=pytest.mark.slow)
        for s in _schedules()
    ]
    + [pytest.param(f"optim={o}", marks=pytest.mark.slow) for o in ("quickprop", "delta_bar_delta", "rprop", "adam")]
    + [pytest.param(f"schedule.order={o}", marks=pytest.mark.slow) for o in ("random", "coverage")],
)
def test_every_schedule_order_and_optimizer_trains_on_it(sarcos, variant):
    from selpres.run.train import train

    cfg = file_cfg(sarcos, variant, "replicas=2", "eval.every=0", "checkpoint.enabled=false")
    res = train(cfg)
    assert res["status"] == "complete"
    assert res["schedule"]["sizes"][-1] == 480
    for key in ("test10_rms_nm_overall", "heldout_rms_nm_overall", "heldout_rms_scaled_overall"):
        assert np.isfinite(res["summary"][key]["mean"])
    raw = OmegaConf.load(CONFIGS / "schedule" / f"{cfg.schedule.name}.yaml")
    if raw.get("budget") is not None:  # the paper's budget on the paper's n, applied by proportion
        assert res["presentations_done"] == round(raw.budget * 480 / 1002)


# --------------------------------------------------------------------------------------------- errors
def _error(path: Path, *overrides: str, **kw) -> ConfigError:
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as ei:
        prepare(resolve(file_cfg(path, *overrides, **kw)))
    assert "\n" not in str(ei.value)
    return ei.value


def test_missing_column_is_named_with_the_columns_there_are(sarcos):
    e = _error(sarcos, inputs=INPUTS[:-1] + ["ddq8"])
    assert isinstance(e, DataFileError) and str(sarcos) in str(e) and "'ddq8'" in str(e) and "'tau7'" in str(e)


@pytest.mark.parametrize(
    "cell, problem",
    [
        ("abc", "'abc' is not a number"),
        ("", "'' is not a number"),
        ("nan", "NaN and inf"),
        ("-inf", "NaN and inf"),
    ],
)
def test_bad_cell_names_file_column_and_line(tmp_path, cell, problem):
    lines = ["a,b,y"] + [f"{i},{i * 2},{i * 3}" for i in range(40)]
    lines[7] = f"6,{cell},18"  # line 8 of the file, column b
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    e = _error(path, inputs=["a", "b"], outputs=["y"])
    assert str(e).startswith(f"{path}: column 'b', line 8: ") and problem in str(e), str(e)


def test_row_with_a_missing_cell_is_named(tmp_path):
    path = tmp_path / "short.csv"
    path.write_text("a,b,y\n" + "".join(f"{i},{i},{i}\n" for i in range(30)) + "1,2\n")
    e = _error(path, inputs=["a", "b"], outputs=["y"])
    assert f"{path}: line 32: has 2 cells, the header names 3" in str(e)


def test_duplicate_header_is_refused(tmp_path):
    path = write_csv(tmp_path / "dup.csv", np.ones((30, 3)), ["a", "y", "a"])
    e = _error(path, inputs=["a"], outputs=["y"])
    assert "column 'a'" in str(e) and "columns 1 and 3" in str(e)


def test_npz_problems_are_named(tmp_path):
    bad = np.arange(40.0)
    bad[17] = np.nan
    np.savez(tmp_path / "nan.npz", a=np.arange(40.0), y=bad)
    e = _error(tmp_path / "nan.npz", inputs=["a"], outputs=["y"])
    assert "column 'y', row 17 (0-based)" in str(e)
    np.savez(tmp_path / "text.npz", a=np.arange(40.0), y=np.array(["x"] * 40))
    assert "dtype <U1" in str(_error(tmp_path / "text.npz", inputs=["a"], outputs=["y"]))


def test_too_few_rows_for_the_schedule_names_the_file(tmp_path):
    path = write_csv(tmp_path / "tiny.csv", np.random.default_rng(0).uniform(size=(12, 2)), ["a", "y"])
    e = _error(path, "data.test_from_exemplar=1", "data.test_patterns=2", inputs=["a"], outputs=["y"])
    assert isinstance(e, DataFileError) and str(e).startswith(f"{path}: rows: 12 rows") and "schedule.sizes" in str(e)


def test_too_few_rows_for_the_split(tmp_path):
    path = write_csv(tmp_path / "three.csv", np.ones((3, 2)), ["a", "y"])
    e = _error(path, inputs=["a"], outputs=["y"])
    assert str(e).startswith(f"{path}: rows: 3: too few")


@pytest.mark.parametrize(
    "overrides, key",
    [
        (["data.path=null"], "data.path"),
        (["data.outputs=[q1]"], "data.outputs"),  # an input too
        (["data.scaling.mode=commanded"], "data.scaling.mode"),
        (["+data.n=5"], "data.n"),  # a key of another kind (the open node takes it with +, the check refuses it)
    ],
)
def test_config_errors_name_the_key(sarcos, overrides, key):
    from selpres.run.resolve import resolve

    cfg = file_cfg(sarcos, *overrides)
    with pytest.raises(ConfigError) as ei:
        resolve(cfg)
        load_task(*task_specs(cfg))
    assert ei.value.key == key, str(ei.value)


def test_missing_file(tmp_path):
    e = _error(tmp_path / "nope.csv", inputs=["a"], outputs=["y"])
    assert str(e) == f"{tmp_path / 'nope.csv'}: file: not found (data.path must name a CSV or .npz file)"


@pytest.mark.slow
def test_command_line_exits_2_and_writes_nothing(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("a,y\n1,2\n3,x\n" + "".join(f"{i},{i}\n" for i in range(40)))
    run = tmp_path / "run"
    out = run_python(
        str(ROOT / "train.py"),
        "data=file",
        f"data.path={path}",
        "data.inputs=[a]",
        "data.outputs=[y]",
        "topology.layers=1-4-1",
        f"hydra.run.dir={run}",
        cwd=tmp_path,
        timeout=300,
    )
    assert out.returncode == 2, out.stderr
    assert f"error: {path}: column 'y', line 3: 'x' is not a number" in out.stderr and "Traceback" not in out.stderr
    assert not run.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


@pytest.mark.parametrize("comments", ["", "# exported by a spreadsheet\n"])
def test_a_csv_with_a_byte_order_mark_reads_as_the_same_text(sarcos, tmp_path, comments):
    """Issue 26: every spreadsheet's "CSV UTF-8" starts with EF BB BF; it was refused as its columns were
    ['\\ufeffq1', ...]. The same file with the mark gives the same task, bit for bit."""
    text = sarcos.read_bytes()
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + comments.encode() + text)
    assert bom.read_bytes()[:3] == b"\xef\xbb\xbf" and not text.startswith(b"\xef\xbb\xbf")
    assert torch.equal(load_columns(bom, ["q1", "tau7"]), load_columns(sarcos, ["q1", "tau7"]))
    a, b = load_task(*task_specs(file_cfg(bom))), load_task(*task_specs(file_cfg(sarcos)))
    assert torch.equal(a.exemplar.X, b.exemplar.X) and torch.equal(a.tests.heldout.Y, b.tests.heldout.Y)
