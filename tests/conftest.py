"""Shared fixtures: paths, the paper's robot/data configs, the real exemplar set, Hydra composition."""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / "configs"
# the studies and benchmarks (studies/: selpres_studies, selpres_bench), the checkout's own first, in this process and
# the processes the tests start (`make setup` installs them editable too, with the report's entry point)
STUDIES = REPO / "studies"
sys.path.insert(0, str(STUDIES))
os.environ["PYTHONPATH"] = os.pathsep.join([str(STUDIES), *filter(None, [os.environ.get("PYTHONPATH")])])

# One torch thread in the test processes and the jobs they start (OMP_NUM_THREADS set beforehand wins): the suite's
# tensors are tiny, and a second intra-op thread only waits for a core: a 6-5-2 backward took 58 ms with 2 threads
# and 2 ms with 1 on a busy 2-core machine, and `make test` already runs two workers (pytest-xdist) on two cores.
# Thread counts that matter are passed explicitly (tests/test_engine.py, tests/test_kernels.py: threads 1, 2, 3).
os.environ.setdefault("OMP_NUM_THREADS", "1")
torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))  # this process's torch read the variable on import

# the tests' own data cache (selpres.data.cache), shared by this session's jobs and the processes they start,
# never the user's ~/.cache; a test about building data turns it off (monkeypatch.setenv("SELPRES_DATA_CACHE", "off"))
os.environ["SELPRES_DATA_CACHE"] = tempfile.mkdtemp(prefix="selpres-test-cache-")
atexit.register(shutil.rmtree, os.environ["SELPRES_DATA_CACHE"], ignore_errors=True)


# The longest files first: `make test` hands whole files to its two workers (--dist loadfile) in collection order,
# and with these last one worker ran alone for ~3 minutes at the end of a CI run (load 1.1-1.5 there). Per-file
# seconds of a CI run (pytest --durations); the order within a file is kept, the other files follow in theirs.
LONGEST_FILES = (
    "test_engine.py",
    "test_resume.py",
    "test_ctrl_c.py",
    "test_sigterm_sweeps.py",
    "test_sigterm.py",
    "test_lightning.py",
    "test_selective_presentation.py",
    "test_reliability.py",
)


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: every other order is kept


def load_group(group: str, option: str):
    """A group file's own values (its Hydra ``defaults`` list, which picks other groups, left out)."""
    cfg = OmegaConf.load(CONFIGS / group / f"{option}.yaml")
    cfg.pop("defaults", None)
    return cfg


@pytest.fixture(scope="session")
def exemplar():
    """The paper's exemplar set (n = 1002) built from configs/robot/two_link.yaml and configs/data/paper.yaml."""
    from selpres.arms.two_link import TwoLinkArm
    from selpres.data.paper import build_exemplar_set

    return build_exemplar_set(TwoLinkArm.from_config(load_group("robot", "two_link")), load_group("data", "paper"))


def compose(*overrides: str, hydra: bool = False):
    """The ``train`` config composed as ``python train.py`` composes it (``selpres.run.config.compose_train``).
    The one place tests compose configs."""
    from selpres.run.config import compose_train

    return compose_train(CONFIGS, list(overrides), hydra)


@pytest.fixture
def compose_cfg():
    """``compose_cfg(*overrides, hydra=False)`` -> the composed ``train`` config."""
    return compose


SMALL = ["data.heldout=300", "eval.heldout_curve=300", "logging.progress=false"]


def cfg_of(*overrides: str):
    """A training config with a small held-out set (fast to prepare); the test's own overrides win."""
    return compose(*SMALL, *overrides)


def numbers(res: dict) -> dict:
    """Everything in results.json that must be reproducible (wall times excluded: the curves' work_seconds too)."""
    curves = [{k: v for k, v in rec.items() if k != "work_seconds"} for rec in res["curves"]]
    return {**{k: res[k] for k in ("summary", "replica_results", "schedule", "config_hash")}, "curves": curves}


def _native_reason() -> str | None:
    """Why the native kernel cannot run here (None when it can): native-only tests skip with this reason."""
    from selpres.native import KernelUnavailable, load

    try:
        load((6, 13, 2))
        return None
    except KernelUnavailable as exc:
        return str(exc).splitlines()[0]


NATIVE_REASON = _native_reason()
requires_native = pytest.mark.skipif(NATIVE_REASON is not None, reason=f"native kernel unavailable: {NATIVE_REASON}")


def run_python(*args: str, timeout: int = 600, cwd=REPO):
    """``python <args>`` as a user runs it (without HYDRA_FULL_ERROR), in ``cwd`` (default: the repository),
    output captured."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def torchrun(script, *args: str, log_dir, timeout: int = 600):
    """``torchrun --standalone --nproc_per_node=2 script args`` (2 CPU processes), its agent's logs under
    ``log_dir`` (by default torchrun makes a /tmp/torchelastic_* folder per run that nothing removes)."""
    return run_python(
        "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2", "--log-dir", str(log_dir), str(script),
        *args, timeout=timeout,
    )  # fmt: skip


def report_of(sweep, out) -> None:
    """``python -m selpres.report sweep --out out``, which must succeed."""
    done = run_python("-m", "selpres.report", str(sweep), "--out", str(out))
    assert done.returncode == 0, done.stderr[-3000:]


def online_engine(requested: str, sizes, params, lr: float, momentum: float, batch_size: int, threads=None):
    """The online SGD engine ``requested`` (fast, native, torch, reference) as a job builds it
    (``selpres.engines.factory.build_engine``): the paper's rule at ``lr``, ``momentum``, on ``batch_size``."""
    from selpres.engines.factory import EngineSpec, build_engine

    return build_engine(EngineSpec.online(requested, sizes, lr, momentum, batch_size, threads), params)
