"""SelectivePresentation as a library caller uses it: arguments, errors naming the argument, the CLI's own sampler,
rank shares against torch's DistributedSampler, the cost counters, the misuse warnings, a real two-process group."""

from __future__ import annotations

import json
import math
import pickle
import shutil
import warnings

import numpy as np
import pytest
import torch
from hypothesis import event, given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf
from torch.utils.data import DataLoader, DistributedSampler, TensorDataset

from selpres.errors import ConfigError
from selpres.presentation.proportions import NAMED
from selpres.presentation.sampler import SelectivePresentation, SelectivePresentationWarning

from conftest import CONFIGS, REPO, cfg_of, run_python, torchrun

FRACTIONS, EPOCHS = [0.05, 0.1, 0.4, 0.8, 1.0], [2, 1, 2, 1, 1]


@pytest.fixture(scope="module")
def X(exemplar):
    return exemplar.X


def _loop(sampler, dataset_size: int, batch_size: int = 16) -> list[list[int]]:
    """Every epoch of a DataLoader loop, as the indices it presented."""
    loader = DataLoader(TensorDataset(torch.arange(dataset_size)), batch_size=batch_size, sampler=sampler)
    out = []
    for epoch in range(sampler.num_epochs):
        sampler.set_epoch(epoch)
        out.append(torch.cat([b[0] for b in loader]).tolist())
    return out


# ------------------------------------------------------------------------------------------ the front door


def test_fractions_counts_and_the_paper_schedule(X):
    n = X.shape[0]
    s = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=0)
    assert s.schedule.sizes == [math.floor(f * n + 0.5) for f in FRACTIONS] == [50, 100, 401, 802, 1002]
    assert s.num_epochs == sum(EPOCHS) == 7 and s.order_kind == "stratified"
    counts = SelectivePresentation(X, sizes=[50, 100, 1002], epochs=[1, 1, 1])
    assert counts.schedule.sizes == [50, 100, 1002]
    paper = SelectivePresentation(X, schedule="selective")
    assert paper.schedule.sizes == [50, 100, 400, 800, 1002] and paper.schedule.presentations == 70_560
    assert paper.num_epochs == 150 and paper.schedule_note is None


def test_named_schedules_are_the_config_files():
    """NAMED (for callers without configs/) holds what configs/schedule/*.yaml hold, with train.yaml's defaults."""
    files = {p.stem: OmegaConf.to_container(OmegaConf.load(p)) for p in (CONFIGS / "schedule").glob("*.yaml")}
    pruning = {name for name, f in files.items() if f.get("pruning")}  # chosen by loss: the CLI's, not a sampler's
    assert {"infobatch", "selective_backprop"} <= pruning
    from selpres.presentation.pruning import REGISTRY

    assert all(REGISTRY.canonical(files[name]["pruning"]["_target_"]) in REGISTRY.names for name in pruning)
    # the parametric schedule (stages.yaml) is the config's; its instances, the presets, are NAMED
    files = {name: f for name, f in files.items() if name not in pruning and "p" not in f}
    assert set(files) == set(NAMED)
    with pytest.raises(ValueError, match="losses.*python train.py schedule=infobatch"):
        SelectivePresentation(torch.rand(100, 6), schedule="infobatch")
    for name, f in files.items():
        want = {"sizes": f["sizes"], "epochs": f.get("epochs"), "budget": f.get("budget"), "order": "stratified"}
        want["order"] = f.get("order", "stratified")
        assert NAMED[name] == want, name


def test_a_named_schedule_on_another_n_uses_the_papers_proportions():
    Xs = torch.rand(5010, 6, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    s = SelectivePresentation(Xs, schedule="selective", seed=1)
    assert s.schedule.sizes == [math.floor(c / 1002 * 5010 + 0.5) for c in [50, 100, 400, 800]] + [5010]
    assert "fractions" in s.schedule_note
    m = SelectivePresentation(Xs, schedule="matched")
    assert m.schedule.presentations == math.floor(70_560 * 5010 / 1002 + 0.5)
    assert SelectivePresentation(n=30, schedule="random_growth").order_kind == "random"


def test_budget_and_orders(X):
    n = X.shape[0]
    b = SelectivePresentation(X, budget=3 * n + 420, seed=2)
    assert b.num_epochs == 4 and b.schedule.presentations == 3 * n + 420
    assert [len(e) for e in _loop(b, n)] == [n, n, n, 420]
    for kind in ("stratified", "random", "coverage"):
        s = SelectivePresentation(X, sizes=[0.1, 1.0], epochs=[1, 1], order=kind, seed=3)
        assert sorted(s.order.tolist()) == list(range(n)) and s.order_kind == kind
    mine = torch.randperm(n, generator=torch.Generator().manual_seed(9))
    own = SelectivePresentation(order=mine, sizes=[0.1, 1.0], epochs=[1, 1])
    assert torch.equal(own.training_set, mine[:100]) and own.order_kind == "given"
    assert SelectivePresentation(n=40, order="random", sizes=[10, 40], epochs=[1, 1]).schedule.n == 40


def test_sizes_from_any_sequence_or_1d_array_round_half_up_and_at_least_one():
    """n = 1002 by hand: 0.0004 n = 0.4008 rounds half up to 0, so it is 1 (at least one pattern); 0.25 n = 250.5
    is 251 half up (Python's round() would give 250); 0.4 n = 400.8 is 401; 1.0 is the whole set."""
    want = [1, 251, 401, 1002]
    fractions = [0.0004, 0.25, 0.4, 1.0]
    for sizes in (fractions, tuple(fractions), np.array(fractions), torch.tensor(fractions, dtype=torch.float64)):
        s = SelectivePresentation(n=1002, order="random", sizes=sizes, epochs=np.array([1, 2, 1, 1]))
        assert s.schedule.sizes == want and s.schedule.epochs == [1, 2, 1, 1], type(sizes)
    for counts in (np.array([50, 100, 1002]), torch.tensor([50, 100, 1002]), range(50, 1003, 476)):
        s = SelectivePresentation(n=1002, order="random", sizes=counts, epochs=[1, 1, 1])
        assert s.schedule.sizes == list(np.asarray(list(counts))), type(counts)  # counts stay counts
    with pytest.raises(TypeError, match=r"sizes: expected a sequence or 1-D array .* got shape \[1, 2\]"):
        SelectivePresentation(n=1002, order="random", sizes=np.array([[0.1, 1.0]]), epochs=[1, 1])
    with pytest.raises(TypeError, match="True is a bool"):
        SelectivePresentation(n=1002, order="random", sizes=np.array([True, True]), epochs=[1, 1])


@pytest.mark.parametrize(
    "kw, error, words",
    [
        ({"sizes": [0.05, 0.1, 1], "epochs": [1, 1, 1]}, ValueError, ["sizes=", "1.0"]),
        ({"sizes": "0.1, 1.0", "epochs": [1, 1]}, TypeError, ["sizes="]),
        ({"sizes": [0.1, "x", 1.0], "epochs": [1, 1, 1]}, TypeError, ["sizes=", "'x'"]),
        ({"sizes": [0.1, 0.05, 1.0], "epochs": [1, 1, 1]}, ValueError, ["sizes=", "increasing"]),
        ({"sizes": [0.1, 1.0], "epochs": [1]}, ValueError, ["epochs=", "one entry per stage"]),
        ({"sizes": [0.1, 1.0], "epochs": [1.5, 2]}, TypeError, ["epochs="]),
        ({"sizes": [0.1, 1.0]}, ValueError, ["epochs=None", "budget"]),
        ({"budget": 0}, ValueError, ["budget=0"]),
        ({"sizes": [0.1, 1.0], "budget": 500}, ValueError, ["budget=500", "one-stage"]),
        ({"sizes": [1.0], "epochs": [2], "budget": 500}, ValueError, ["epochs=[2]", "None when budget"]),
        ({"schedule": "fast"}, ValueError, ["schedule='fast'", "selective"]),
        ({"schedule": "selective", "sizes": [1.0]}, TypeError, ["either a schedule or sizes"]),
        ({"schedule": "selective", "order": "loss_high"}, ValueError, ["order='loss_high'", "CLI"]),
        ({"schedule": "selective", "order": "zigzag"}, ValueError, ["order='zigzag'", "stratified"]),
        ({"schedule": "selective", "order": [0, 0, 1]}, ValueError, ["disagree"]),
        ({"schedule": "selective", "seed": -1}, ValueError, ["seed=-1"]),
        ({"schedule": "selective", "seed": 1.5}, TypeError, ["seed=1.5"]),
        ({"schedule": "selective", "strata_bins": 0}, ValueError, ["strata_bins=0"]),
        ({"schedule": "selective", "num_replicas": 0}, ValueError, ["num_replicas=0"]),
        ({"schedule": "selective", "num_replicas": 2, "rank": 2}, ValueError, ["rank=2"]),
    ],
)
def test_library_errors_name_the_argument(X, kw, error, words):
    with pytest.raises(error) as e:
        SelectivePresentation(X, **kw)
    assert type(e.value) is error  # a plain one: not the CLI's ConfigError
    msg = str(e.value)
    assert all(w in msg for w in words), msg
    assert "schedule." not in msg and "null" not in msg and "\n" not in msg


_ANY = st.one_of(
    st.none(),
    st.sampled_from([[1.0], [10, 40], [0.25, 1.0], [0.1, 0.5, 40], [1, 2], [2], 100]),  # some that build
    st.integers(-3, 60),
    st.floats(-0.5, 1.5),
    st.booleans(),
    st.text(max_size=3),
    st.lists(st.one_of(st.integers(-3, 60), st.floats(-0.5, 1.5), st.just(float("nan")), st.booleans()), max_size=5),
)


_BUILDS = st.one_of(  # (sizes, epochs, budget) that build
    st.tuples(st.sampled_from([[10, 40], [0.25, 1.0], [0.1, 0.5, 40]]), st.just(None), st.just(None)).map(
        lambda t: (t[0], [2] * len(t[0]), None)
    ),
    st.tuples(st.just([1.0]), st.just(None), st.integers(1, 150)),
)


@settings(max_examples=200, deadline=None)
@given(args=st.one_of(_BUILDS, st.tuples(_ANY, _ANY, _ANY)), seed=st.one_of(st.integers(0, 9), _ANY))
def test_any_arguments_build_or_raise_a_plain_error_naming_one(args, seed):
    """Whatever a caller passes: a sampler whose epochs present exactly its plan, or a one-line ValueError /
    TypeError (never the CLI's ConfigError, never another exception) that starts with an argument's name."""
    sizes, epochs, budget = args
    try:
        s = SelectivePresentation(n=40, order="random", sizes=sizes, epochs=epochs, budget=budget, seed=seed)
    except (ValueError, TypeError) as e:
        assert not isinstance(e, ConfigError)
        assert str(e).split("=")[0].split(":")[0] in ("sizes", "epochs", "budget", "seed"), str(e)
        assert "\n" not in str(e) and "schedule." not in str(e)
        return
    event("built")
    total = 0
    for epoch in range(s.num_epochs):
        s.set_epoch(epoch)
        got = list(s)
        assert len(got) == len(s) and set(got) <= set(s.training_set.tolist())
        total += len(got)
    assert total == s.presentations == s.schedule.presentations


def test_a_sampler_pickles_midway(X):
    """Spawned workers and launchers pickle what they are given: the copy continues the same epoch."""
    s = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=2)
    s.set_epoch(3)
    it = iter(s)
    [next(it) for _ in range(5)]
    copy = pickle.loads(pickle.dumps(s))
    assert copy.epoch == 3 and copy.presentations == s.presentations
    assert torch.equal(copy.epoch_indices(), s.epoch_indices())


def test_errors_about_the_data():
    with pytest.raises(ValueError, match="X: the inputs hold NaN"):
        SelectivePresentation(torch.tensor([[0.0], [float("nan")]]), sizes=[1.0], epochs=[1])
    with pytest.raises(TypeError, match="needs the inputs X"):
        SelectivePresentation(n=10, sizes=[1.0], epochs=[1])
    with pytest.raises(ValueError, match=r"permutation of range\(3\)"):
        SelectivePresentation(order=[0, 0, 1], sizes=[1.0], epochs=[1])
    with pytest.raises(ValueError, match="schedule='selective' on n = 3"):
        SelectivePresentation(n=3, order="random", schedule="selective")


def test_the_cli_keeps_its_config_key_messages():
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as e:
        prepare(resolve(cfg_of("schedule.sizes=[0.05,0.1,1]", "schedule.epochs=[1,1,1]")))
    assert e.value.key == "schedule.sizes"


def test_the_library_sampler_is_the_clis_replica(X):
    """One implementation: seed s with the raw exemplar inputs gives exactly the order and every epoch of the CLI
    job's replica whose seed is s (replica r of seed=4 has seed 4 + r)."""
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    prob = prepare(resolve(cfg_of("schedule=selective", "seed=4", "replicas=2")))
    for r, cli in enumerate(prob.samplers):
        mine = SelectivePresentation(prob.task.exemplar.X, schedule="selective", seed=4 + r)
        assert type(cli) is SelectivePresentation
        assert torch.equal(mine.order, cli.order)
        for epoch in (0, 31, 149):
            mine.set_epoch(epoch)
            cli.set_epoch(epoch)
            assert torch.equal(mine.epoch_indices(), cli.epoch_indices())


# ------------------------------------------------------------------------------------------ distribution


def _torch_shares(epoch_order: list[int], world: int, drop_last: bool) -> list[list[int]]:
    """What torch's own DistributedSampler gives each rank from this epoch order (unshuffled: the order is the
    dataset), the independent reference for padding and drop_last."""
    return [
        [epoch_order[i] for i in DistributedSampler(epoch_order, world, r, shuffle=False, drop_last=drop_last)]
        for r in range(world)
    ]


@pytest.mark.parametrize("world", [1, 2, 3, 4])
@pytest.mark.parametrize("drop_last", [False, True])
def test_rank_shares_are_distributed_samplers(X, world, drop_last):
    n = X.shape[0]
    kw = {"sizes": FRACTIONS, "epochs": EPOCHS, "seed": 7, "num_replicas": world, "drop_last": drop_last}
    ranks = [SelectivePresentation(X, rank=r, **kw) for r in range(world)]
    per_rank = [_loop(s, n) for s in ranks]
    plan = ranks[0].schedule.plan()
    for p in plan:
        for s in ranks:
            s.set_epoch(p.index)
        order = ranks[0].epoch_indices().tolist()
        assert all(s.epoch_indices().tolist() == order for s in ranks)  # every rank computes the same epoch
        shares = [per_rank[r][p.index] for r in range(world)]
        assert shares == _torch_shares(order, world, drop_last)
        assert all(len(sh) == len(ranks[0]) for sh in shares)
        union = [i for sh in shares for i in sh]
        if p.size % world == 0 or drop_last:
            assert len(set(union)) == len(union)  # disjoint
        if p.size % world == 0 or not drop_last:
            assert set(union) == set(ranks[0].training_set.tolist())  # exactly the training set A_i


def test_presentation_counters(X):
    """After each epoch: per rank the sum of what it was handed; globally world x that; planned counts by hand."""
    n, world = X.shape[0], 3
    sizes = [50, 100, 401, 802, 1002]
    s = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=1, num_replicas=world, rank=1)
    loader = DataLoader(TensorDataset(torch.arange(n)), batch_size=32, sampler=s)
    per_epoch = [size for size, e in zip(sizes, EPOCHS) for _ in range(e)]
    handed = 0
    for epoch in range(s.num_epochs):
        s.set_epoch(epoch)
        assert s.rank_presentations == handed  # before the epoch: the epochs before it
        got = sum(b[0].numel() for b in loader)
        handed += got
        assert got == math.ceil(per_epoch[epoch] / world) == len(s)
        assert s.rank_presentations == handed and s.presentations == world * handed
    one = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=1)
    _loop(one, n)
    assert one.presentations == sum(size * e for size, e in zip(sizes, EPOCHS)) == one.schedule.presentations
    fresh = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=1)
    fresh.set_epoch(4)  # jumping to an epoch presents nothing by itself: the counter says what was handed out
    assert fresh.presentations == 0
    it = iter(fresh)
    [next(it) for _ in range(10)]
    assert fresh.presentations == 10
    resumed = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=1)
    resumed.load_state_dict({"epoch": 4, "position": 10, "rank_presentations": 50 * 2 + 100 + 401 + 10})
    assert resumed.presentations == 50 * 2 + 100 + 401 + 10  # a resumed run's count comes with its state
    resumed.set_epoch(4)
    assert len(list(resumed)) == 401 - 10 and resumed.presentations == 50 * 2 + 100 + 401 + 401  # epoch 4: A3


def test_without_a_process_group_it_is_one_rank(X):
    s = SelectivePresentation(X, schedule="selective")
    assert (s.num_replicas, s.rank) == (1, 0) and not torch.distributed.is_initialized()
    assert isinstance(s, DistributedSampler)  # so Lightning and other wrappers leave it unwrapped


# ------------------------------------------------------------------------------------------ misuse is loud


def test_a_second_pass_without_set_epoch_warns_once(X):
    s = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=0)
    loader = DataLoader(TensorDataset(torch.arange(X.shape[0])), batch_size=64, sampler=s)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):  # the bug: no set_epoch
            for _ in loader:
                pass
    mine = [w for w in caught if issubclass(w.category, SelectivePresentationWarning)]
    assert len(mine) == 1
    assert "set_epoch(epoch)" in str(mine[0].message) and "for epoch in range(sampler.num_epochs)" in str(
        mine[0].message
    )


def test_a_correct_loop_is_silent_and_a_cut_epoch_warns(X):
    s = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SelectivePresentationWarning)
        _loop(s, X.shape[0])
        s.set_epoch(0)
        list(s)  # back at epoch 0 after the last: a new epoch, not a repeat
    s.set_epoch(2)
    it = iter(s)
    [next(it) for _ in range(64)]  # a loop sized by A1 stops here
    with pytest.warns(SelectivePresentationWarning, match="epoch 2 presented 64 of its 100 patterns"):
        s.set_epoch(3)


def test_set_epoch_past_the_schedule_says_what_to_do(X):
    s = SelectivePresentation(X, sizes=FRACTIONS, epochs=EPOCHS)
    with pytest.raises(IndexError, match=r"epoch=7 is outside the schedule's 7 epochs.*num_epochs"):
        s.set_epoch(7)
    with pytest.raises(TypeError, match="epoch=1.0: expected a whole number"):
        s.set_epoch(1.0)
    s.set_epoch(np.int64(2))
    assert s.stage == 1


# ------------------------------------------------------------------------------------------ a real process group


@pytest.mark.slow
@pytest.mark.parametrize("drop_last", [False, True])
def test_two_gloo_processes_share_every_epoch(tmp_path, drop_last):
    """torchrun, 2 CPU processes, gloo: each rank reads its rank from the group, the ranks compute the same epoch
    order without communicating, their shares are torch's DistributedSampler's of it (disjoint, union = A_i when
    the size divides, padded by the head or cut otherwise), and the counters agree."""
    out = tmp_path / "ranks.json"
    done = torchrun(
        REPO / "tests" / "ddp_app.py", str(out), *(["--drop-last"] if drop_last else []), log_dir=tmp_path / "logs"
    )
    assert done.returncode == 0, done.stderr[-3000:]
    got = json.loads(out.read_text())
    assert got["world"] == 2
    sizes, handed = [], 0
    for ranks in got["epochs"]:
        order, subset = ranks[0]["epoch_order"], set(ranks[0]["training_set"])
        assert all(r["epoch_order"] == order and set(r["training_set"]) == subset for r in ranks)
        assert sorted(order) == sorted(subset)
        shares = [r["share"] for r in ranks]
        assert shares == _torch_shares(order, 2, drop_last)
        union = shares[0] + shares[1]
        if len(subset) % 2 == 0:
            assert len(set(union)) == len(union) and set(union) == subset
        elif drop_last:
            assert len(set(union)) == len(union) == len(subset) - 1
        else:
            assert set(union) == subset and len(union) == len(subset) + 1
        handed += len(shares[0])
        assert all(r["rank_presentations"] == handed and r["presentations"] == 2 * handed for r in ranks)
        sizes.append(len(subset))
    assert sizes == [10, 10, 25, 51, 51, 101]  # 0.1, 0.25, 0.5 of 101 rounded half up; 2, 1, 2, 1 epochs


@pytest.mark.slow
def test_examples_run(tmp_path):
    """The four examples, as README shows them, on the exported two-link data with 2 epochs per stage; the resume
    example killed (SIGKILL) mid-epoch and run again ends on the uninterrupted run's weights."""
    done = run_python("-m", "selpres.run.export", "--out", str(tmp_path / "twolink"))
    assert done.returncode == 0, done.stderr[-3000:]
    data = str(tmp_path / "twolink.npz")
    for f in ("plain_loop.py", "ddp_torchrun.py", "lightning_fit.py", "resume_loop.py", "twolink.py"):
        shutil.copy(REPO / "examples" / f, tmp_path / f)  # as a user's copy, outside the repository
    plain = run_python(str(tmp_path / "plain_loop.py"), "--data", data, "--epochs", "2", cwd=tmp_path)
    assert plain.returncode == 0, plain.stderr[-3000:]
    lines = plain.stdout.splitlines()
    assert len(lines) == 5 and lines[-1].startswith("stage 5: 1002 patterns, 4,710 presentations so far")
    ddp = torchrun(tmp_path / "ddp_torchrun.py", "--data", data, "--epochs", "2", log_dir=tmp_path / "logs")
    assert ddp.returncode == 0, ddp.stderr[-3000:]
    assert "stage 5: 1002 patterns, 501 per rank, 4,712 presentations so far" in ddp.stdout  # 401 padded to 402
    light = run_python(str(tmp_path / "lightning_fit.py"), "--data", data, "--epochs", "2", cwd=tmp_path)
    assert light.returncode == 0, light.stderr[-3000:]
    assert "10 epochs, 4,710 presentations (the schedule's 4,710)" in light.stdout

    def resume_loop(*args):
        return run_python(str(tmp_path / "resume_loop.py"), "--data", data, "--epochs", "2", *args, cwd=tmp_path)

    full = resume_loop("--ckpt", "full.pt")
    assert full.returncode == 0, full.stderr[-3000:]
    killed = resume_loop("--ckpt", "run.pt", "--kill-in", "5")  # epoch 5: A3, 401 patterns, 13 batches of 32
    assert killed.returncode == -9 and killed.stdout.strip() == "killed in epoch 5 after pattern 160"
    resumed = resume_loop("--ckpt", "run.pt")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert resumed.stdout.splitlines()[0] == "resumed in epoch 5 at pattern 160 of 401"
    last = full.stdout.splitlines()[-1]
    assert resumed.stdout.splitlines()[-1] == last and last.startswith("4,710 presentations, held-out RMS")


def test_the_bench_row_runs(capsys):
    """studies/selpres_bench/sampler.py on a small set: one row per loop kind, both samplers present n every epoch."""
    from selpres_bench.sampler import bench_sampler

    bench_sampler(quick=True, n=3000, batch=64)
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("sampler  ")]
    assert [r.split()[1] for r in rows] == ["TensorDataset", "batch-indexed", "sampler"]
