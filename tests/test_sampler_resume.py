"""The Sampler resumes mid-epoch exactly (its own state_dict, through torchdata's StatefulDataLoader with 0 and 2
workers, in one process and in a real 2-process gloo group), counts what it handed out, and each warning names its
cause."""

from __future__ import annotations

import gc
import json
import math
import warnings

import pytest
import torch
from torch.utils.data import DataLoader, TensorDataset

from selpres.presentation.sampler import SelectivePresentation, SelectivePresentationWarning

from conftest import REPO, torchrun

StatefulDataLoader = pytest.importorskip("torchdata.stateful_dataloader").StatefulDataLoader

N, SIZES, EPOCHS = 100, [20, 50, 100], [2, 1, 2]  # 5 epochs of 20, 20, 50, 100, 100
DATA = TensorDataset(torch.arange(N))


def _sampler(**kw) -> SelectivePresentation:
    return SelectivePresentation(n=N, order="random", sizes=SIZES, epochs=EPOCHS, seed=4, **kw)


def _full(loader_of) -> list[list[int]]:
    sampler, loader = loader_of()
    out = []
    for epoch in range(sampler.num_epochs):
        sampler.set_epoch(epoch)
        out.append([i for (b,) in loader for i in b.tolist()])
    return out


@pytest.fixture(autouse=True)
def _quiet_interrupted_runs():
    """An interrupted run's sampler, collected, says its last epoch was stopped: expected here, not under test."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*set_vital")  # torchdata calls a deprecated torch function
        warnings.filterwarnings("ignore", message=r".*the schedule's last, presented")
        yield
        gc.collect()


@pytest.mark.parametrize("workers", [0, 2])
def test_a_stateful_dataloader_resumes_mid_epoch_exactly(workers):
    """Stop after b batches of epoch e (at an epoch's start, inside it, at its last batch), save the loader's state,
    resume with a fresh sampler and loader and the natural loop: every epoch presents exactly what the
    uninterrupted run presented, in the same order, and the counter ends at the schedule's cost."""

    def loader_of():
        s = _sampler()
        return s, StatefulDataLoader(DATA, batch_size=8, sampler=s, num_workers=workers)

    full = _full(loader_of)
    assert [len(e) for e in full] == [20, 20, 50, 100, 100]
    stops = [(0, 1), (2, 3), (2, 7), (3, 6), (4, 12)] if workers == 0 else [(2, 3), (4, 12)]  # 7: A2's last batch
    for stop_epoch, stop_batches in stops:
        sampler, loader = loader_of()
        seen = [[] for _ in full]
        for epoch in range(stop_epoch + 1):
            sampler.set_epoch(epoch)
            for k, (b,) in enumerate(loader):
                seen[epoch] += b.tolist()
                if epoch == stop_epoch and k + 1 == stop_batches:
                    break
        saved = {"epoch": stop_epoch, "loader": loader.state_dict()}
        del sampler, loader

        sampler, loader = loader_of()
        loader.load_state_dict(saved["loader"])
        with warnings.catch_warnings():
            warnings.simplefilter("error", SelectivePresentationWarning)
            for epoch in range(saved["epoch"], sampler.num_epochs):
                sampler.set_epoch(epoch)
                for (b,) in loader:
                    seen[epoch] += b.tolist()
        assert seen == full, (stop_epoch, stop_batches, [len(e) for e in seen])
        assert sampler.presentations == sampler.schedule.presentations == 290


def test_a_plain_loop_resumes_from_the_samplers_own_state():
    """Without torchdata: keep sampler.state_dict() beside the epoch; a fresh sampler loads it, and set_epoch with
    the saved epoch keeps the position (mid-epoch), or moves on (a state saved at an epoch's end)."""

    def loader_of():
        s = _sampler()
        return s, DataLoader(DATA, batch_size=8, sampler=s)

    full = _full(loader_of)
    for stop_epoch, stop_batches, saved_epoch in [(3, 5, 3), (2, 7, 3), (2, 7, 2)]:  # 7 batches: all of A2
        sampler, loader = loader_of()
        seen = [[] for _ in full]
        for epoch in range(stop_epoch + 1):
            sampler.set_epoch(epoch)
            for k, (b,) in enumerate(loader):
                seen[epoch] += b.tolist()
                if epoch == stop_epoch and k + 1 == stop_batches:
                    break
        state = sampler.state_dict()
        handed = sum(len(e) for e in seen)
        assert state == {"epoch": stop_epoch, "position": min(8 * stop_batches, 50), "rank_presentations": handed}
        sampler, loader = loader_of()
        sampler.load_state_dict(state)
        for epoch in range(saved_epoch, sampler.num_epochs):
            sampler.set_epoch(epoch)
            for (b,) in loader:
                seen[epoch] += b.tolist()
        assert seen == full and sampler.presentations == 290


def test_a_state_for_another_epoch_or_place_is_refused():
    s = _sampler()
    s.set_epoch(4)
    with pytest.raises(ValueError, match=r"state is at epoch 2 \(pattern 8 of 50\) but set_epoch\(4\).*range\(2, "):
        s.load_state_dict({"epoch": 2, "position": 8, "rank_presentations": 48})
    with pytest.raises(ValueError, match=r"state\['position'\]=60: epoch 2 hands out 50"):
        _sampler().load_state_dict({"epoch": 2, "position": 60, "rank_presentations": 100})
    with pytest.raises(ValueError, match=r"state\['epoch'\]=5: this sampler's schedule has 5 epochs"):
        _sampler().load_state_dict({"epoch": 5, "position": 0, "rank_presentations": 0})
    with pytest.raises(ValueError, match="expected a SelectivePresentation state_dict"):
        _sampler().load_state_dict({"epoch": 1})


@pytest.mark.slow
def test_two_gloo_processes_resume_each_rank_from_its_own_state(tmp_path):
    """torchrun, 2 CPU processes, gloo, StatefulDataLoader with 0 and 2 workers: each rank saves its own loader
    state mid-epoch, a second torchrun resumes from it, and every rank's epochs are the uninterrupted run's."""
    for mode in ("stop", "resume"):
        done = torchrun(REPO / "tests" / "resume_app.py", str(tmp_path), mode, log_dir=tmp_path / "logs")
        assert done.returncode == 0, done.stderr[-3000:]
    shares = []
    for rank in (0, 1):
        stop = json.loads((tmp_path / f"stop-{rank}.json").read_text())
        resume = json.loads((tmp_path / f"resume-{rank}.json").read_text())
        for workers in ("0", "2"):
            full, before, after = stop[workers]["full"], stop[workers]["seen"], resume[workers]["seen"]
            assert len(before[3]) == 20 and 0 < len(after[3]) == len(full[3]) - 20  # stopped inside epoch 3
            assert [a + b for a, b in zip(before, after)] == full, (rank, workers)
            assert resume[workers]["counter"] == 2 * sum(map(len, full)) == 2 * (5 + 5 + 13 + 26 + 26 + 51)
        shares.append(stop["0"]["full"])
    sizes = [10, 10, 25, 51, 51, 101]  # 0.1, 0.25, 0.5, 1.0 of 101, half up
    for e, size in enumerate(sizes):  # the ranks' shares: disjoint, together the epoch (odd sizes padded by one)
        union = shares[0][e] + shares[1][e]
        assert len(set(union)) == size and len(union) == 2 * math.ceil(size / 2)


# ------------------------------------------------------------------------------------------ the counter


def test_the_counter_counts_what_was_handed_out():
    """A loop sized by the first epoch's len(loader) (3 batches of 8: 24, then 20 in A1's epochs), passes without
    set_epoch, a stopped last epoch: the counter is the number of indices the loader received, by hand."""
    s = _sampler()
    loader = DataLoader(DATA, batch_size=8, sampler=s)
    batches, handed = len(loader), 0  # 3: A1's 20 patterns
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SelectivePresentationWarning)
        for epoch in range(s.num_epochs):
            s.set_epoch(epoch)
            handed += sum(b.numel() for _, (b,) in zip(range(batches), loader))
    assert handed == 20 + 20 + 24 + 24 + 24 and s.presentations == handed == 112

    s = _sampler()  # no set_epoch: six passes over A1
    loader = DataLoader(DATA, batch_size=8, sampler=s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SelectivePresentationWarning)
        handed = sum(b.numel() for _ in range(6) for (b,) in loader)
    assert handed == 120 and s.presentations == 120

    s = _sampler(num_replicas=2, rank=1)  # two ranks: this rank's count, and world x it
    for epoch in range(s.num_epochs):
        s.set_epoch(epoch)
        it = iter(s)
        [next(it) for _ in range(3 if epoch == s.num_epochs - 1 else len(s))]  # the last epoch stopped after 3
    assert s.rank_presentations == 10 + 10 + 25 + 50 + 3 and s.presentations == 2 * 98
    s.finish()  # (its warning is tested below)


@pytest.mark.parametrize("loader_kind", [DataLoader, StatefulDataLoader])
def test_a_stage_that_would_present_nothing_is_an_error(loader_kind):
    """A1 = 20 patterns and DataLoader(batch_size=64, drop_last=True): no batch of A1 is ever formed."""
    loader = loader_kind(DATA, batch_size=64, sampler=_sampler(), drop_last=True)
    with pytest.raises(ValueError, match=r"A_1 presents 20 patterns .*batch_size=64, drop_last=True.*batch_size <= 20"):
        list(loader)
    two = loader_kind(DATA, batch_size=16, sampler=_sampler(num_replicas=2, rank=0), drop_last=True)
    with pytest.raises(ValueError, match=r"A_1 presents 20 patterns an epoch \(10 per rank of 2\).*batch_size=16"):
        list(two)
    assert len([b for (b,) in loader_kind(DATA, batch_size=16, sampler=_sampler(), drop_last=True)]) == 1  # 20 // 16


# ------------------------------------------------------------------------------------------ warnings name their cause


def _one_warning(action) -> str:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        action()
    mine = [str(w.message) for w in caught if issubclass(w.category, SelectivePresentationWarning)]
    assert len(mine) == 1, mine
    return mine[0]


def test_a_repeated_set_epoch_is_named_as_such():
    s = _sampler()
    loader = DataLoader(DATA, batch_size=8, sampler=s)

    def twice():
        for _ in range(2):
            s.set_epoch(1)
            list(loader)

    msg = _one_warning(twice)
    assert "set_epoch(1) was called again after its pass" in msg and "without set_epoch" not in msg
    s2 = _sampler()
    msg = _one_warning(lambda: [list(DataLoader(DATA, batch_size=8, sampler=s2)) for _ in range(2)])
    assert "without set_epoch" in msg


def test_a_resume_that_moves_on_too_early_is_named():
    s = _sampler()
    s.load_state_dict({"epoch": 2, "position": 8, "rank_presentations": 48})
    msg = _one_warning(lambda: s.set_epoch(3))
    assert "epoch 2 was resumed at pattern 8 of its 50 (load_state_dict) but set_epoch(3)" in msg
    assert "range(2, sampler.num_epochs)" in msg and s.presentations == 48  # nothing more was handed out


def test_a_stopped_last_epoch_warns_when_the_sampler_goes():
    s = _sampler()
    for epoch in range(s.num_epochs):
        s.set_epoch(epoch)
        list(DataLoader(DATA, batch_size=8, sampler=s)) if epoch < 4 else [b for _, b in zip(range(2), s)]

    def collect():
        nonlocal s
        del s
        gc.collect()

    msg = _one_warning(collect)
    assert msg.startswith("epoch 4, the schedule's last, presented 2 of its 100 patterns: the loop stopped")
    assert "counts the 192 handed out" in msg  # 20 + 20 + 50 + 100 + 2
    done = _sampler()
    with warnings.catch_warnings():
        warnings.simplefilter("error", SelectivePresentationWarning)
        for epoch in range(done.num_epochs):
            done.set_epoch(epoch)
            list(DataLoader(DATA, batch_size=8, sampler=done))
        done.finish()
        del done
        gc.collect()
