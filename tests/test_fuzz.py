"""Fuzzing the inputs: random topologies and schedules either train correctly or are refused cleanly.

"Cleanly" means a ConfigError (which the CLI turns into one line and exit code 2); anything else that
escapes is a bug. "Correctly" means the run presents exactly the schedule's presentations, every epoch
a permutation (prefix) of the current nested subset, and ends with finite results.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from selpres.data.task import Shape
from selpres.errors import ConfigError
from selpres.run.checks import check_topology
from selpres.run.problem import prepare
from selpres.run.resolve import resolve
from selpres.run.train import train

from conftest import compose

PAPER_SHAPE = Shape(tuple("abcdef"), ("t1", "t2"), "robot=two_link")  # 6 inputs, 2 outputs

widths = st.one_of(st.integers(0, 12).map(str), st.sampled_from(["x", "", "-1", "1.5", " 6", "08"]))
junk_topologies = st.lists(widths, min_size=1, max_size=5).map("-".join)
valid_topologies = st.lists(st.integers(1, 9), min_size=1, max_size=2).map(lambda h: "-".join(map(str, [6, *h, 2])))
topologies = st.one_of(valid_topologies, junk_topologies)
sizes_item = st.one_of(st.integers(-5, 1100), st.floats(-0.5, 1.5), st.sampled_from([float("nan"), float("inf")]))
junk_schedules = st.tuples(
    st.lists(sizes_item, min_size=1, max_size=4), st.lists(st.integers(-1, 2), min_size=1, max_size=4)
)


@st.composite
def valid_schedules(draw):
    """Nested stages ending at n = 1002, as counts or fractions, one or two epochs each."""
    head = sorted(draw(st.sets(st.integers(1, 300), max_size=3)))
    sizes = [*head, 1002]
    if draw(st.booleans()):
        sizes = [*(round(v / 1002, 4) for v in head), 1.0]
    return sizes, draw(st.lists(st.integers(1, 2), min_size=len(sizes), max_size=len(sizes)))


schedules = st.one_of(valid_schedules(), junk_schedules)


def _literal(v) -> str:
    return repr(v) if isinstance(v, float) and v == v and abs(v) != float("inf") else str(v)


@example("6-08-2")
@given(junk_topologies)
def test_topology_strings_parse_or_are_refused(text):
    try:
        sizes = check_topology(text, PAPER_SHAPE)
    except ConfigError as e:
        assert e.key == "topology.layers" and e.allowed and "topology.layers=" in str(e)
        return
    assert sizes[0] == 6 and sizes[-1] == 2 and all(s > 0 for s in sizes)
    assert sizes == tuple(int(w) for w in text.strip().split("-"))  # "6-08-2" is (6, 8, 2)


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(topology=topologies, schedule=schedules, batch=st.integers(1, 3))
def test_every_config_trains_or_is_refused_cleanly(topology, schedule, batch):
    sizes, epochs = schedule
    sizes_txt = "[" + ",".join(_literal(v) for v in sizes) + "]"
    overrides = [
        f"topology.layers='{topology}'",
        f"schedule.sizes={sizes_txt}",
        f"schedule.epochs=[{','.join(map(str, epochs))}]",
        f"optim.batch_size={batch}",
        "engine=torch",
        "replicas=2",
        "data.heldout=50",
        "eval.heldout_curve=50",
        "logging.progress=false",
    ]
    try:
        cfg = compose(*overrides)
    except Exception as e:  # Hydra's own parse/type errors are clean too (one message, exit 1)
        assert type(e).__module__.startswith(("hydra", "omegaconf")), repr(e)
        event("refused by Hydra/omegaconf")
        return
    try:
        prob = prepare(resolve(cfg))
    except ConfigError:
        event("refused: ConfigError")
        return
    plan = prob.schedule.plan()
    if sum(p.presentations for p in plan) > 4000:  # valid but slow: the sampler property is checked elsewhere
        event("valid, too long to train here")
        return
    event("trained")
    res = train(cfg)
    assert res["presentations_done"] == prob.schedule.presentations == sum(p.presentations for p in plan)
    assert res["status"] == "complete"
    assert all(v is not None for v in res["curves"][-1]["train_mse"])
    for s in prob.samplers:  # every epoch: a permutation prefix of the current nested subset
        for p in plan:
            s.set_epoch(p.index)
            idx = s.epoch_indices().tolist()
            assert len(idx) == len(set(idx)) == p.presentations
            assert set(idx) <= set(s.subset().tolist())


@pytest.mark.parametrize("bad", ["6-x-2", "6-0-2", "5-8-2", "6-8-3", "6", "6--2", "-6-2"])
def test_named_bad_topologies_are_config_errors(bad):
    with pytest.raises(ConfigError) as ei:
        prepare(resolve(compose(f"topology.layers='{bad}'")))
    assert ei.value.key == "topology.layers" and bad in str(ei.value)
