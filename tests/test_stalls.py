"""Stalls as an outcome (selpres.run.stalls): the dead and linear hidden units of a net built by hand so that
some are dead or always on by construction, checked against an independent derivation (an ``nn.Module`` with
forward hooks and autograd's derivative of each unit), and the record a real job writes."""

from __future__ import annotations

import json

import pytest
import torch

from selpres.engines.model import BPN, load_into
from selpres.run.stalls import STALL_SHARE, TOL, is_stalled, unit_states
from selpres.run.train import train

from conftest import cfg_of


def _hand_built(activation: str) -> list[torch.Tensor]:
    """Two replicas of a 3-4-3-2 net on inputs in [0, 1]: in replica 0, layer 1's unit 0 is dead (its bias far below
    what its weights can reach), unit 1 always on (bias far above), units 2, 3 bend; in replica 1 nothing is forced.
    Layer 2's unit 2 of replica 1 is dead too."""
    g = torch.Generator().manual_seed(0)
    W1, b1 = torch.rand(2, 4, 3, generator=g, dtype=torch.float64) - 0.5, torch.zeros(2, 4, dtype=torch.float64)
    W2, b2 = torch.rand(2, 3, 4, generator=g, dtype=torch.float64) - 0.5, torch.zeros(2, 3, dtype=torch.float64)
    W3, b3 = torch.rand(2, 2, 3, generator=g, dtype=torch.float64), torch.zeros(2, 2, dtype=torch.float64)
    b1[0, 0], b1[0, 1] = -50.0, 50.0
    W1[0, 2], b1[0, 2] = torch.tensor([4.0, -4.0, 0.0], dtype=torch.float64), 0.0  # crosses 0 inside the box
    W1[0, 3], b1[0, 3] = torch.tensor([0.0, 6.0, -3.0], dtype=torch.float64), 0.0
    W1[1] = torch.tensor([[3.0, -3, 0], [0, 3, -3], [-3, 0, 3], [3, 3, -3]], dtype=torch.float64)
    W2[1] = torch.tensor([[2.0, -2, 0, 0], [0, 2, -2, 0], [0, 0, 0, 0]], dtype=torch.float64)
    b2[1] = torch.tensor([0.0, 0.0, -50.0], dtype=torch.float64)
    return [W1, b1, W2, b2, W3, b3]


def _by_autograd(params, X, activation: str, replica: int):
    """Each hidden unit's derivative d a / d z on every input, from an nn.Module's forward hooks and autograd
    (not the activation class's prime): per hidden layer, a [n, H] tensor."""
    net = load_into(BPN((3, 4, 3, 2), activation=activation), params, replica)
    zs = []
    hooks = [layer.register_forward_hook(lambda m, i, o: zs.append(o)) for layer in net.layers[:-1]]
    net(X)
    for h in hooks:
        h.remove()
    f = getattr(torch, activation) if activation != "relu" else torch.relu
    out = []
    for z in zs:
        z = z.detach().requires_grad_(True)
        (d,) = torch.autograd.grad(f(z).sum(), z)  # elementwise: d a_j / d z_j on every input
        out.append(d)
    return out


@pytest.mark.parametrize("activation", ["relu", "sigmoid", "tanh"])
def test_dead_and_linear_units_against_autograd(activation):
    params = _hand_built(activation)
    X = torch.rand(500, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    states = unit_states(params, X, activation)
    assert [tuple(d.shape) for d, _ in states] == [(2, 4), (2, 3)]
    for r in range(2):
        for (dead, linear), d in zip(states, _by_autograd(params, X, activation, r)):
            lo, hi = d.min(0).values, d.max(0).values
            want_dead = (lo.abs() <= TOL) & (hi.abs() <= TOL)
            assert dead[r].tolist() == want_dead.tolist()
            assert linear[r].tolist() == (~want_dead & (hi - lo <= TOL)).tolist()


def test_the_units_dead_by_construction_are_found():
    X = torch.rand(500, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    (dead1, lin1), (dead2, _) = unit_states(_hand_built("relu"), X, "relu")
    assert dead1[0].tolist() == [True, False, False, False]  # bias -50: never active
    assert lin1[0].tolist() == [False, True, False, False]  # bias +50: always on
    assert dead2[1].tolist() == [False, False, True]
    # sigmoid: bias -50 and +50 both saturate (derivative ~e^-50): both dead, none linear
    (dead1, lin1), _ = unit_states(_hand_built("sigmoid"), X, "sigmoid")
    assert dead1[0].tolist() == [True, True, False, False] and not lin1[0].any()
    # in blocks of inputs or all at once: the same counts
    import selpres.run.stalls as stalls

    small = stalls.CHUNK
    try:
        stalls.CHUNK = 7
        again = unit_states(_hand_built("relu"), X, "relu")
    finally:
        stalls.CHUNK = small
    assert [t.tolist() for pair in again for t in pair] == [
        t.tolist() for pair in unit_states(_hand_built("relu"), X, "relu") for t in pair
    ]


def test_is_stalled():
    assert is_stalled(STALL_SHARE * 4.0, 4.0) is True  # at the threshold: stalled
    assert is_stalled(STALL_SHARE * 4.0 - 1e-9, 4.0) is False
    assert is_stalled(None, 4.0) is None and is_stalled(1.0, None) is None and is_stalled(1.0, 0.0) is None
    assert is_stalled(float("nan"), 4.0) is None


def test_a_job_records_each_replicas_stall_and_units(tmp_path):
    cfg = cfg_of("schedule=conventional", "schedule.epochs=[3]", "replicas=3", "optim=adam_minibatch",
                 "model.activation=relu", "optim.lr=0.01")  # fmt: skip
    res = train(cfg, tmp_path)
    on_disk = json.loads((tmp_path / "results.json").read_text())
    st = on_disk["stalls"]
    assert st["threshold"] == STALL_SHARE and st["hidden_units"] == 13 and st["units_on"] == "heldout"
    floor = on_disk["floor"]["heldout"]["nm"]["overall"]
    for rep, s in zip(res["replica_results"], st["replicas"]):
        rms = rep["final"]["heldout"]["nm"]["overall"]
        assert s["seed"] == rep["seed"] and s["share_of_floor"] == pytest.approx(rms / floor)
        assert s["stalled"] == (rms >= STALL_SHARE * floor)
        assert 0 <= s["dead"] + s["linear"] <= 13
    # the counts are those of the trained weights on the held-out inputs
    weights = torch.load(tmp_path / "weights.pt", weights_only=False)
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    X = prepare(resolve(cfg)).scored["heldout"][0]
    dead, linear = unit_states(weights["params"], X, "relu")[0]
    assert [s["dead"] for s in st["replicas"]] == dead.sum(1).tolist()
    assert [s["linear"] for s in st["replicas"]] == linear.sum(1).tolist()
