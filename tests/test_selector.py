"""The one selector protocol and the one ledger (issue 37): costs charged by hand, the ledger's one-number path
against its per-replica one, every selector's state round trip, names of what ran, and the clock's nested phases."""

from __future__ import annotations

import io

import pytest
import torch

from selpres.presentation.build import SelectorSpec, build_selector
from selpres.presentation.pruning.infobatch import InfoBatch
from selpres.presentation.schedule import EpochPlan, Schedule, Stage
from selpres.presentation.selector import Ledger, Network, Presentation, Selector

from conftest import cfg_of


def _ledger(budget=None, seeds=(0, 1), n=10):
    return Ledger(n, list(seeds), budget, None if budget else 4, 1 / 3)


def test_a_whole_epoch_and_a_cut_one_are_charged_by_hand():
    led = _ledger()
    led.record(Presentation(torch.zeros(2, 10, dtype=torch.int64)), EpochPlan(0, 0, 10, 10))
    led.charge(2.5)  # forward passes, every replica alike
    led.record(Presentation(torch.zeros(2, 10, dtype=torch.int64), None, torch.tensor([7, 0])), EpochPlan(1, 0, 10, 10))
    led.charge(1 / 3, replica=1)
    d = led.describe()["per_replica"]
    assert d["trained"] == [17.0, 10.0] and d["charged"] == [2.5, 2.5 + 1 / 3]
    assert d["spent"] == [19.5, 12.5 + 1 / 3] and d["epochs"] == [2, 1]
    assert d["conventional"] == [20.0, 10.0]  # conventional training presents all of U in the epochs each ran
    assert led.describe()["cost_ratio"] == (19.5 + 12.5 + 1 / 3) / 30


def test_a_compute_matched_plans_cut_epoch_counts_its_share_of_conventional():
    led = _ledger(seeds=(0,), n=1002)
    for ep in Schedule((Stage(1002, 2, 420),)).plan():
        led.record(Presentation(torch.zeros(1, ep.presentations, dtype=torch.int64)), ep)
    d = led.describe()
    assert d["presentations"] == d["conventional_presentations"] == 2 * 1002 + 420 and d["cost_ratio"] == 1.0
    assert isinstance(d["presentations"], int)  # whole presentations are written whole


def test_one_number_per_row_is_the_per_replica_ledger_exactly():
    """A staged job keeps one number per row (its replicas are charged alike); splitting it at any point gives
    the tensors it would have kept, and both read alike (engine clock, means, budget)."""
    shown = Presentation(torch.zeros(3, 7, dtype=torch.int64))
    even, split = _ledger(budget=30, seeds=(0, 1, 2)), _ledger(budget=30, seeds=(0, 1, 2))
    split.spent  # noqa: B018  (reading a row splits it)
    for led in (even, split):
        for e in range(3):
            led.charge(1 / 3 * 5)
            led.record(shown, EpochPlan(e, 0, 10, 10))
    assert even._rows is None and split._rows is not None
    assert even.describe() == split.describe()
    assert torch.equal(torch.as_tensor(even.clock()).expand(3), split.clock())
    assert even.mean("spent") == split.mean("spent") and even.exhausted == split.exhausted is False
    even.record(shown, EpochPlan(3, 0, 10, 10))
    split.record(shown, EpochPlan(3, 0, 10, 10))
    assert even.exhausted and split.exhausted  # 35 of 30 spent


def test_presented_masks_only_a_replica_that_presented_nothing():
    loss = torch.tensor([float("nan"), float("nan"), 0.5])
    masked = Presentation(torch.zeros(3, 2, dtype=torch.int64), None, torch.tensor([0, 2, 2])).presented(loss)
    assert masked[0] == 0 and masked[1].isnan() and masked[2] == 0.5  # a diverged replica stays NaN
    assert Presentation(torch.zeros(3, 2, dtype=torch.int64)).presented(loss) is loss


def _roundtrip(obj):
    buf = io.BytesIO()
    torch.save(obj.state_dict(), buf)
    return torch.load(io.BytesIO(buf.getvalue()), weights_only=True)  # as a checkpoint reads it back


def test_ledger_and_policy_states_round_trip_and_refuse_what_does_not_fit():
    led = _ledger(budget=100)
    pol = InfoBatch(InfoBatch.check({"prune_ratio": 0.5, "delta": 0.875}, budget=100, selection_cost=1 / 3), led)
    led.charge(3.0, replica=0)
    pol.scores[1, 4] = 0.25
    pol.annealing.on[0] = True
    led_state, pol_state = _roundtrip(led), _roundtrip(pol)
    led2 = _ledger(budget=100)
    pol2 = InfoBatch(dict(pol.params), led2)
    led2.load_state_dict(led_state)
    pol2.load_state_dict(pol_state)
    assert led2.describe() == led.describe()
    assert torch.equal(pol2.scores, pol.scores) and torch.equal(pol2.annealing.on, pol.annealing.on)
    assert set(pol_state) == {"scores", "annealing"}  # the ledger is the loop's, saved once
    with pytest.raises(ValueError, match="scores"):
        pol2.load_state_dict({**pol_state, "scores": torch.zeros(3, 10, dtype=torch.float64)})
    with pytest.raises(ValueError, match="holds"):
        pol2.load_state_dict({"scores": pol.scores})
    with pytest.raises(ValueError):
        _ledger(budget=100, seeds=(0, 1, 2)).load_state_dict(led_state)


def _built(target=None, order="stratified", params=None, budget=None, epochs=(2, 2)):
    X = torch.rand(40, 6, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    Y = torch.rand(40, 2, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    sizes = [1.0] if target else [10, 40]
    spec = SelectorSpec(order=order, target=target, params=params or {})
    from selpres.presentation.build import plan

    node = {"sizes": sizes, "epochs": None if budget else list(epochs[: len(sizes)]), "budget": budget}
    schedule, _, budget = plan(spec, node, 40)
    return build_selector(spec, schedule, [0, 1], X, X, Y, budget)


def test_what_ran_is_named_a_builtin_by_its_name_a_users_class_by_its_path():
    staged, _ = _built()
    assert (staged.name, staged.identity["order_name"], staged.identity["user_classes"]) == ("staged", "stratified", [])
    params = {"prune_ratio": 0.5, "delta": 0.875}
    by_path, _ = _built("selpres.presentation.pruning.infobatch.InfoBatch", "random", params)
    by_name, _ = _built("infobatch", "random", params)
    assert by_path.identity == by_name.identity  # a built-in named by its import path is still the built-in
    assert by_name.identity["name"] == "infobatch" and by_name.identity["class"].endswith("infobatch.InfoBatch")

    class Mine(Selector):
        pass

    Mine.__module__, Mine.__qualname__ = "my_pkg.sel", "Mine"
    from selpres.presentation.build import identity
    from selpres.presentation.orders import REGISTRY as ORDERS
    from selpres.presentation.orders.random import Random
    from selpres.presentation.pruning import REGISTRY as SELECTORS

    got = identity([("selector", SELECTORS, Mine), ("order", ORDERS, Random)])
    assert got == {
        "name": "my_pkg.sel.Mine",
        "class": "my_pkg.sel.Mine",
        "order_name": "random",
        "order_class": "selpres.presentation.orders.random.Random",
        "user_classes": ["my_pkg.sel.Mine"],
    }


class _Engine:
    """Stands in for an engine where only predict is asked (one replica per row of ``out``)."""

    def __init__(self, R):
        self.R = R

    def predict(self, X):
        return torch.zeros(self.R, X.shape[0], 2, dtype=torch.float64)


def test_every_selector_answers_the_one_call_and_charges_what_it_scores():
    """The staged presentation of a stage-wise order charges its candidates at its stage start, every replica
    alike; Selective Backprop charges each scored candidate; the loop's own call is the same for both."""
    staged, led = _built(order="loss_high")
    net = Network(_Engine(2), staged.X, staged.Y)
    plan = staged.schedule.plan()
    for ep in plan:
        shown = staged.select(ep, led, net)
        assert shown.order.shape == (2, ep.presentations) and shown.counts is None
        led.record(shown, ep)
    assert led.describe()["per_replica"]["charged"] == [10.0, 10.0]  # 30 candidates x 1/3, rounded up: 10
    sb, led = _built("selective_backprop", "random", {"beta": 1.0}, epochs=(3,))
    for ep in sb.source.schedule.plan():
        shown = sb.select(ep, led, Network(_Engine(2), sb.source.X, sb.source.Y))
        led.record(shown, ep)
    assert led.describe()["per_replica"]["charged"] == pytest.approx([3 * 40 / 3] * 2)  # every candidate, 3 epochs


def test_the_clocks_nested_phases_count_each_second_once(monkeypatch):
    from selpres.run import train as T

    now = [0.0]
    monkeypatch.setattr(T.time, "perf_counter", lambda: now[0])
    clock = T.Clock()
    with clock("loop"):
        with clock("select"):
            now[0] += 1.0
            with clock("shuffle"):
                now[0] += 2.0
            now[0] += 0.5
        with clock("train"):
            now[0] += 4.0
    assert clock.seconds["select"] == 1.5 and clock.seconds["shuffle"] == 2.0 and clock.seconds["train"] == 4.0
    assert clock.work() == 7.5 and clock.seconds["loop"] == 7.5  # the loop's phase is not a method's: whole


def test_a_job_of_every_kind_has_one_selector_and_one_ledger():
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    for overrides in (
        [],
        ["schedule.order=loss_high"],
        ["schedule=infobatch", "schedule.epochs=[3]"],
        ["schedule=seta", "schedule.epochs=null", "schedule.budget=5000"],
    ):
        prob = prepare(resolve(cfg_of(*overrides, "replicas=2")))
        assert isinstance(prob.selector, Selector) and isinstance(prob.ledger, Ledger)
        assert prob.selector.source.samplers is prob.samplers and len(prob.samplers) == 2
        assert not hasattr(prob, "pruning") and not hasattr(prob, "selection")


def test_the_loop_asks_every_method_the_same_and_never_which_it_has():
    """The loop, the engines and results.json name no kind of method: every job goes through one selector and one
    ledger (a branch such as ``if prob.pruning`` would come back here)."""
    import inspect
    import re

    from selpres.engines import batch, minibatch, native_minibatch, online
    from selpres.run import results, train

    kinds = re.compile(r"\.(pruning|selection)\b|stagewise|Policy|StageSelection|isinstance\([^)]*(Staged|Policy)")
    for module in (train, results, online, batch, minibatch, native_minibatch):
        code = "\n".join(line.split("#")[0] for line in inspect.getsource(module).splitlines())
        code = re.sub(r'"""(.|\n)*?"""', "", code)  # docstrings may name the methods they serve
        assert not kinds.search(code.replace("cfg.schedule.pruning", "")), (module.__name__, kinds.search(code))
