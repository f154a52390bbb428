"""The one engine factory (selpres.engines.factory): every engine meets the protocol the loop uses, the mode is chosen
from the optimizer, units and rate, a request an engine cannot serve is refused naming ``engine``, ``fast`` falls
back once and says why, and the run/ room builds engines through the factory alone."""

from __future__ import annotations

import ast
import logging
import typing
from pathlib import Path

import pytest
import torch

from selpres.engines.factory import (
    ENGINES,
    Engine,
    EngineSpec,
    build_engine,
    check_request,
    mode_for,
    mode_of,
)
from selpres.engines.model import init_replica_params
from selpres.errors import ConfigError

from conftest import REPO, requires_native

SIZES = (6, 5, 2)
SPECS = {
    "online": EngineSpec.online("torch", SIZES, 0.15, 0.9),
    "minibatch": EngineSpec("torch", "minibatch", SIZES, "adam", {"lr": 0.01}, 4, "relu", "cosine", 100.0),
    "batch": EngineSpec("torch", "batch", SIZES, "quickprop", {"lr": 0.001}, 0, reduction="sum"),
}


def _protocol_members() -> set[str]:
    members = {n for n in vars(Engine) if not n.startswith("_")}
    return members | set(typing.get_type_hints(Engine))


@pytest.mark.parametrize("key", sorted(ENGINES))
def test_every_registered_engine_offers_what_the_loop_calls(key):
    """Built from its spec, each engine has every member of the protocol, ``last_losses`` included, and trains an
    epoch, leaving ``last_losses`` [R, 0] after an epoch that is not pruned."""
    mode, impl = key
    if impl == "native":
        pytest.importorskip("selpres.native")
        from conftest import NATIVE_REASON

        if NATIVE_REASON is not None:
            pytest.skip(NATIVE_REASON)
    R = 3
    eng = build_engine(SPECS[mode].replace(requested=impl), init_replica_params(SIZES, list(range(R))))
    assert type(eng) is ENGINES[key] and eng.name == ENGINES[key].name
    missing = sorted(m for m in _protocol_members() if not hasattr(eng, m))
    assert not missing, f"{ENGINES[key].__name__} lacks {missing}"
    X = torch.rand(20, SIZES[0], dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    Y = torch.rand(20, SIZES[-1], dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    loss = eng.train_epoch(X, Y, torch.arange(20).repeat(R, 1))
    assert loss.shape == (R,) and eng.last_losses.shape[0] == R
    assert eng.squared_errors(X, Y).shape == (R, SIZES[-1]) and eng.finite().all()
    assert mode_of(eng.name) == mode


@pytest.mark.parametrize(
    "args, mode, lacks",
    [
        (("sgd", ("online", "minibatch", "batch"), 1, "sigmoid", "constant"), "online", None),
        (("sgd", ("online", "minibatch", "batch"), 32, "sigmoid", "constant"), "online", None),
        (("sgd", ("online", "minibatch", "batch"), 1, "tanh", "constant"), "minibatch", "model.activation=tanh"),
        (("sgd", ("online", "minibatch", "batch"), 1, "sigmoid", "cosine"), "minibatch", "optim.lr_schedule=cosine"),
        (("adam", ("minibatch", "batch"), 32, "sigmoid", "constant"), "minibatch", "optim._target_=adam"),
        (("adam", ("minibatch", "batch"), 0, "sigmoid", "constant"), "batch", None),
        (("quickprop", ("batch",), 1, "sigmoid", "constant"), "batch", None),
    ],
)
def test_the_mode_follows_the_optimizer_the_units_and_the_rate(args, mode, lacks):
    got, why = mode_for(*args)
    assert got == mode
    if lacks:
        assert lacks in why
    if mode == "online":
        assert why is None


@pytest.mark.parametrize(
    "requested, mode, allowed",
    [
        ("reference", "minibatch", "fast, native or torch"),
        ("native", "batch", "fast or torch"),
        ("reference", "batch", "fast or torch"),
    ],
)
def test_a_request_the_mode_has_no_engine_for_is_refused_naming_engine(requested, mode, allowed):
    with pytest.raises(ConfigError) as e:
        check_request(requested, mode, "because")
    assert e.value.key == "engine" and e.value.value == requested
    assert e.value.allowed.startswith(f"{allowed}: because")


def test_an_unknown_request_names_every_choice():
    with pytest.raises(ConfigError, match="one of fast, native, torch, reference"):
        check_request("gpu", "online")
    for mode in ("online", "minibatch", "batch"):
        check_request("fast", mode)  # fast: every mode
        check_request("torch", mode)


def test_fast_falls_back_once_saying_why_and_native_is_refused(monkeypatch, caplog):
    """Where no kernel can run, ``fast`` runs torch with the reason recorded and logged once, in every mode that has
    a kernel; ``native`` is a ConfigError, never a silent fallback; batch mode has no kernel and no fallback."""
    monkeypatch.setenv("SELPRES_NO_NATIVE", "1")
    for mode in ("online", "minibatch"):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="selpres"):
            eng = build_engine(SPECS[mode].replace(requested="fast"), init_replica_params(SIZES, [0]))
        assert eng.name == ENGINES[(mode, "torch")].name and eng.fallback_reason == "disabled by SELPRES_NO_NATIVE"
        (line,) = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        assert line.startswith(f"engine 'fast' runs the {eng.name} engine") and "SELPRES_NO_NATIVE" in line
        with pytest.raises(ConfigError, match="engine='native'"):
            build_engine(SPECS[mode].replace(requested="native"), init_replica_params(SIZES, [0]))
    eng = build_engine(SPECS["batch"].replace(requested="fast"), init_replica_params(SIZES, [0]))
    assert eng.name == "batch" and eng.fallback_reason is None


@requires_native
def test_fast_is_native_where_the_kernel_runs(caplog):
    with caplog.at_level(logging.WARNING, logger="selpres"):
        online = build_engine(SPECS["online"].replace(requested="fast"), init_replica_params(SIZES, [0]))
        minibatch = build_engine(SPECS["minibatch"].replace(requested="fast"), init_replica_params(SIZES, [0]))
    assert (online.name, minibatch.name) == ("native", "minibatch-native")
    assert online.fallback_reason is None and minibatch.fallback_reason is None and not caplog.records


def test_an_optimizer_the_kernel_lacks_runs_on_torch_under_fast_and_is_said():
    """Rprop on mini-batches: the native mini-batch kernel has no such rule; ``fast`` runs torch, saying so."""
    spec = EngineSpec("fast", "minibatch", SIZES, "rprop", {"lr": 0.01}, 4)
    eng = build_engine(spec, init_replica_params(SIZES, [0]))
    assert eng.name == "minibatch" and "optim._target_=rprop" in eng.fallback_reason


def test_records_older_than_the_engine_name_are_online():
    assert mode_of(None) == "online" and mode_of("native") == "online" and mode_of("minibatch-native") == "minibatch"
    assert mode_of("batch") == "batch"


def test_run_builds_engines_through_the_factory_alone():
    """No module of selpres/run imports an engine class or builds one but through ``build_engine``: one place
    chooses."""
    classes = {cls.__name__ for cls in ENGINES.values()}
    for path in sorted((REPO / "selpres" / "run").glob("*.py")):
        tree = ast.parse(Path(path).read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("selpres.engines"):
                names = {a.name for a in node.names}
                assert not names & classes, f"{path.name} imports {names & classes} from {node.module}"
