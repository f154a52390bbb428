"""The native mini-batch kernel against the definition of correct: one BPN + one torch.optim optimizer per replica
(autograd, written here, independently of either engine), and against the torch mini-batch engine; then what a job
records, its thread- and replica-independence and its checkpoints."""

from __future__ import annotations

import json
import logging
import math

import pytest
import torch

from selpres.engines.minibatch import MiniBatchEngine
from selpres.engines.model import BPN, init_replica_params, load_into
from selpres.engines.native_minibatch import NativeMiniBatchEngine, native_reason

from conftest import cfg_of, requires_native

SIZES = (6, 5, 4, 2)
N, M, B, EPOCHS = 40, 23, 4, 3  # 23 = 5 batches of 4 and an uneven last one of 3
TOL = 1e-12  # relative: |native - reference| <= TOL * max |reference| of each replica's tensor


def _hparams(rule: str) -> dict:
    """The config's keys of each rule (selpres.engines.optim: SGD takes lr and momentum, Adam/AdamW weight decay)."""
    if rule == "sgd":
        return {"lr": 0.05, "momentum": 0.9}
    return {"lr": 0.01, "weight_decay": 0.01}


def _epochs(R: int):
    """Three epochs: a whole one, then two pruned (each replica its own count, a weight per pattern)."""
    g = torch.Generator().manual_seed(5)
    X, Y = torch.rand(N, 6, generator=g, dtype=torch.float64), torch.rand(N, 2, generator=g, dtype=torch.float64)
    counts = torch.tensor([M, M - 6, 9, 0, 4][:R] + [M - r for r in range(max(0, R - 5))])
    out = []
    for e in range(EPOCHS):
        order = torch.randint(0, N, (R, M), generator=g)
        w = 0.5 + torch.rand(R, M, generator=g, dtype=torch.float64)
        out.append((order, None, None) if e == 0 else (order, w, counts))
    return X, Y, out


def _per_replica_loop(params, r, rule, hp, activation, X, Y, epochs, horizon, reduction, batch=B):
    """Replica r as a PyTorch user trains it: a BPN, torch.optim, autograd, the cosine rate set per step."""
    model = load_into(BPN(SIZES, activation=activation), params, r)
    wd = hp.get("weight_decay", 0.0)
    if rule == "sgd":
        opt = torch.optim.SGD(model.parameters(), lr=hp["lr"], momentum=hp["momentum"], weight_decay=wd)
    else:
        make = torch.optim.Adam if rule == "adam" else torch.optim.AdamW
        opt = make(model.parameters(), lr=hp["lr"], weight_decay=wd)
    spent, losses = 0, []
    for order, w, counts in epochs:
        c = order.shape[1] if counts is None else int(counts[r])
        per_pattern = torch.full((order.shape[1],), math.nan, dtype=torch.float64)
        for s in range(0, c, batch):
            idx = order[r, s : min(s + batch, c)]
            for group in opt.param_groups:
                group["lr"] = hp["lr"] * 0.5 * (1 + math.cos(math.pi * min(spent / horizon, 1.0)))
            sq = (model(X[idx]) - Y[idx]).square()
            weight = 1.0 if w is None else w[r, s : s + len(idx)]
            if reduction == "mean":
                loss = (weight * sq.mean(-1)).mean()
            else:  # Rumelhart's 1/2 sum of e^2, each pattern weighted
                loss = 0.5 * (weight * sq.sum(-1)).sum()
            opt.zero_grad()
            loss.backward()
            opt.step()
            per_pattern[s : s + len(idx)] = sq.mean(-1).detach()
            spent += len(idx)
        losses.append(per_pattern)
    return [p.detach() for p in model.flat_params()], losses


def _close(got: torch.Tensor, want: torch.Tensor) -> float:
    """max |got - want| / max |want|: the relative disagreement of a tensor."""
    return float((got - want).abs().max() / want.abs().max().clamp(min=1e-300))


CASES = [(a, rule, "mean") for a in ("sigmoid", "tanh", "relu", "silu") for rule in ("sgd", "adam", "adamw")]


@requires_native
@pytest.mark.parametrize("R", [1, 3, 13])
@pytest.mark.parametrize("activation, rule, reduction", [*CASES, ("relu", "adam", "sum"), ("tanh", "sgd", "sum")])
def test_native_equals_per_replica_torch_optim_and_the_torch_engine(activation, rule, reduction, R):
    X, Y, epochs = _epochs(R)
    params = init_replica_params(SIZES, [10 + r for r in range(R)])
    hp, horizon = _hparams(rule), 2.5 * M  # the cosine reaches zero inside the third epoch
    engines = [
        cls(SIZES, params, rule, dict(hp), B, activation, "cosine", horizon, reduction)
        for cls in (NativeMiniBatchEngine, MiniBatchEngine)
    ]
    native, torch_engine = engines
    assert native.name == "minibatch-native"
    for order, w, counts in epochs:
        got, want = (e.train_epoch(X, Y, order, weights=w, counts=counts) for e in engines)
        torch.testing.assert_close(got, want, rtol=TOL, atol=0, equal_nan=True)
        torch.testing.assert_close(native.last_losses, torch_engine.last_losses, rtol=TOL, atol=0, equal_nan=True)
    assert torch.equal(native.spent, torch_engine.spent)
    worst = 0.0
    for r in range(R):
        ref, ref_losses = _per_replica_loop(params, r, rule, hp, activation, X, Y, epochs, horizon, reduction)
        for got, via_torch, want in zip(native.params(), torch_engine.params(), ref):
            worst = max(worst, _close(got[r], want), _close(got[r], via_torch[r]))
        torch.testing.assert_close(native.last_losses[r], ref_losses[-1], rtol=TOL, atol=0, equal_nan=True)
    assert worst <= TOL
    moved = max(_close(a, b) for a, b in zip(native.params(), params))
    assert moved > 1e-3  # it trained (a kernel that did nothing would fail above, but say it plainly)


@requires_native
@pytest.mark.parametrize("batch", [1, 2 * M])  # online (a step per pattern), and one mini-batch an epoch
@pytest.mark.parametrize("activation, rule", [("relu", "adam"), ("sigmoid", "sgd"), ("silu", "adamw")])
def test_native_equals_per_replica_torch_optim_at_batch_1_and_a_whole_epoch(activation, rule, batch):
    R = 3
    X, Y, epochs = _epochs(R)
    params = init_replica_params(SIZES, [10 + r for r in range(R)])
    hp = _hparams(rule)
    native = NativeMiniBatchEngine(SIZES, params, rule, dict(hp), batch, activation, "cosine", 2.5 * M)
    for order, w, counts in epochs:
        native.train_epoch(X, Y, order, weights=w, counts=counts)
    for r in range(R):
        ref, _ = _per_replica_loop(params, r, rule, hp, activation, X, Y, epochs, 2.5 * M, "mean", batch)
        assert max(_close(got[r], want) for got, want in zip(native.params(), ref)) <= TOL


@requires_native
def test_a_pruned_replica_with_nothing_left_keeps_its_weights_bit_for_bit():
    R = 5
    X, Y, epochs = _epochs(R)
    params = init_replica_params(SIZES, list(range(R)))
    eng = NativeMiniBatchEngine(SIZES, params, "adam", {"lr": 0.01}, B, "relu")
    order, w, counts = epochs[1]
    assert int(counts[3]) == 0
    eng.train_epoch(X, Y, order, weights=w, counts=counts)
    assert all(torch.equal(a[3], b[3]) for a, b in zip(eng.params(), params))
    assert eng.spent.tolist() == counts.double().tolist()
    assert torch.isnan(eng.last_losses[3]).all() and not torch.isnan(eng.last_losses[0]).any()


@requires_native
def test_numbers_do_not_depend_on_threads_on_replicas_together_or_on_the_run():
    """Threads take groups of 4 replicas; a replica's numbers are the same however the groups are split, whichever
    replicas share its vector, and run after run."""
    sizes, n, R = (6, 13, 2), 400, 13
    g = torch.Generator().manual_seed(3)
    X, Y = torch.rand(n, 6, generator=g, dtype=torch.float64), torch.rand(n, 2, generator=g, dtype=torch.float64)
    orders = [torch.argsort(torch.rand(R, n, generator=g), dim=1) for _ in range(2)]
    params = init_replica_params(sizes, list(range(R)))

    def run(threads, keep=range(R)):
        keep = list(keep)
        eng = NativeMiniBatchEngine(
            sizes, [p[keep] for p in params], "adamw", {"lr": 0.01}, 32, "silu", "cosine", 2 * n, threads=threads
        )
        for o in orders:
            eng.train_epoch(X, Y, o[keep])
        return eng

    one, two = run(1), run(2)
    P = sum(p[0].numel() for p in params)
    assert two._k.threads_for(3 * 16 * n * P, 2) == 2  # the epoch really is split between two threads
    assert all(torch.equal(a, b) for a, b in zip(one.params(), two.params()))
    assert all(torch.equal(a, b) for a, b in zip(one.params(), run(2).params()))
    alone = run(1, [7])  # replica 7 trained by itself (its lanes' neighbours: copies of it)
    assert all(torch.equal(a[7], b[0]) for a, b in zip(one.params(), alone.params()))


@requires_native
def test_a_checkpoint_resumes_exactly():
    X, Y, epochs = _epochs(3)
    params = init_replica_params(SIZES, [0, 1, 2])
    make = lambda: NativeMiniBatchEngine(SIZES, params, "adam", {"lr": 0.01}, B, "tanh", "cosine", 3 * M)  # noqa: E731
    straight, resumed = make(), make()
    straight.train_epoch(X, Y, epochs[0][0])
    resumed.load_state_dict(straight.state_dict())
    for eng in (straight, resumed):
        order, w, counts = epochs[1]
        eng.train_epoch(X, Y, order, weights=w, counts=counts)
    assert all(torch.equal(a, b) for a, b in zip(straight.params(), resumed.params()))
    assert torch.equal(straight.spent, resumed.spent)


@requires_native
def test_a_checkpoint_of_the_torch_engine_is_refused_not_misread():
    """The torch engine lays out its optimizer's state otherwise: the kernel refuses it (the checkpoint code then
    moves the file aside and starts afresh) rather than resume from moments it would misread."""
    X, Y, epochs = _epochs(3)
    params = init_replica_params(SIZES, [0, 1, 2])
    args = (SIZES, params, "adam", _hparams("adam"), B, "relu", "cosine", 3 * M)
    on_torch = MiniBatchEngine(*args)
    on_torch.train_epoch(X, Y, epochs[0][0])
    with pytest.raises(ValueError, match="another mini-batch engine"):
        NativeMiniBatchEngine(*args).load_state_dict(on_torch.state_dict())


def test_what_the_kernel_cannot_run_is_named():
    assert native_reason("adam", "relu", "cosine", "mean", {"lr": 0.1, "beta1": 0.9}) is None
    assert "optim._target_=rprop" in native_reason("rprop", "relu", "cosine", "mean", {})
    assert "model.activation=gelu" in native_reason("adam", "gelu", "constant", "mean", {})
    assert "optim.mu" in native_reason("sgd", "relu", "constant", "mean", {"mu": 1.5})
    assert native_reason("sgd", "relu", "constant", "mean", {"mu": None}) is None


def test_fast_falls_back_to_the_torch_engine_and_says_why(monkeypatch, caplog):
    from selpres.engines.factory import EngineSpec, build_engine
    from selpres.errors import ConfigError

    monkeypatch.setenv("SELPRES_NO_NATIVE", "1")
    params = init_replica_params(SIZES, [0])
    spec = EngineSpec("fast", "minibatch", SIZES, "adam", {"lr": 0.01}, B, "relu", "cosine", 100.0)
    with caplog.at_level(logging.WARNING, logger="selpres"):
        eng = build_engine(spec, params)
    assert eng.name == "minibatch" and eng.fallback_reason == "disabled by SELPRES_NO_NATIVE"
    (line,) = [r.getMessage() for r in caplog.records if r.name == "selpres" and r.levelno == logging.WARNING]
    assert line == (
        "engine 'fast' runs the minibatch engine: the native minibatch kernel cannot run this job: "
        "disabled by SELPRES_NO_NATIVE"
    )
    with pytest.raises(ConfigError, match="engine='native'.*fast or torch.*disabled by SELPRES_NO_NATIVE"):
        build_engine(spec.replace(requested="native"), params)
    assert build_engine(spec.replace(requested="torch"), params).fallback_reason is None


JOB = ["optim=adam_minibatch", "model.activation=relu", "replicas=3", "schedule.epochs=[2,2,2,2,2]"]


@requires_native
def test_a_job_records_the_engine_that_ran_and_both_agree(tmp_path, monkeypatch):
    from selpres.run.train import train

    res = {}
    for engine in ("fast", "native", "torch"):
        monkeypatch.chdir(tmp_path)
        res[engine] = train(cfg_of(*JOB, f"engine={engine}"))
    for engine, ran in (("fast", "minibatch-native"), ("native", "minibatch-native"), ("torch", "minibatch")):
        assert (res[engine]["engine"], res[engine]["engine_requested"]) == (ran, engine)
        assert res[engine]["engine_fallback"] is None
    assert json.dumps(res["fast"]["summary"]) == json.dumps(res["native"]["summary"])  # the same numbers
    a, b = (res[e]["summary"]["heldout_rms_nm_overall"]["mean"] for e in ("native", "torch"))
    assert a == pytest.approx(b, rel=1e-9, abs=0)
    monkeypatch.setenv("SELPRES_NO_NATIVE", "1")
    fell = train(cfg_of(*JOB, "engine=fast"))
    assert fell["engine"] == "minibatch" and "disabled by SELPRES_NO_NATIVE" in fell["engine_fallback"]
    assert json.dumps(fell["summary"]) == json.dumps(res["torch"]["summary"])


def test_engine_native_is_accepted_for_mini_batch_jobs_and_reference_is_not():
    from selpres.errors import ConfigError
    from selpres.run.resolve import resolve

    resolve(cfg_of(*JOB, "engine=native"))
    resolve(cfg_of(*JOB, "engine=torch"))
    with pytest.raises(ConfigError, match="engine='reference'.*fast, native or torch: .*model.activation=relu"):
        resolve(cfg_of(*JOB, "engine=reference"))


def test_engine_native_where_the_kernel_cannot_run_is_a_config_error(monkeypatch):
    from selpres.errors import ConfigError
    from selpres.run.problem import job_engine, prepare
    from selpres.run.resolve import resolve

    monkeypatch.setenv("SELPRES_NO_NATIVE", "1")
    cfg = cfg_of(*JOB, "engine=native")
    with pytest.raises(ConfigError, match="disabled by SELPRES_NO_NATIVE"):
        job = resolve(cfg)
        job_engine(job, prepare(job))


@requires_native
def test_a_key_left_unset_gets_the_registrys_default_on_both_engines():
    """``optim.weight_decay=null`` with AdamW: the registry's default (0.01) on both engines, so they still agree."""
    from selpres.run.problem import job_engine, prepare
    from selpres.run.resolve import resolve

    engines = []
    order = torch.randint(0, 300, (3, 64), generator=torch.Generator().manual_seed(0))
    for engine in ("native", "torch"):
        cfg = cfg_of(*JOB, "optim._target_=adamw", "optim.weight_decay=null", f"engine={engine}")
        job = resolve(cfg)
        prob = prepare(job)
        eng = job_engine(job, prob)
        eng.train_epoch(prob.X, prob.Y, order)
        engines.append(eng)
    assert [e.name for e in engines] == ["minibatch-native", "minibatch"]
    for a, b in zip(*(e.params() for e in engines)):
        assert _close(a, b) <= TOL
    o = cfg.optim
    for wd, same in ((0.01, True), (0.0, False)):
        hp = {"lr": o.lr, "beta1": o.beta1, "beta2": o.beta2, "eps": o.eps, "weight_decay": wd}
        args = (prob.sizes, prob.init_params, "adamw", hp, o.batch_size, "relu", o.lr_schedule, prob.budget)
        explicit = NativeMiniBatchEngine(*args)
        explicit.train_epoch(prob.X, prob.Y, order)
        assert all(torch.equal(a, b) for a, b in zip(explicit.params(), engines[0].params())) == same
