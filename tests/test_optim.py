"""The section-2 optimizers against hand-derived steps (numbers worked out by hand, written below)."""

from __future__ import annotations

import math

import pytest
import torch

from selpres.engines.optim import DeltaBarDelta, QuickProp, make_optimizer, offset_sigmoid
from selpres.errors import ConfigError


def _descend(opt_factory, energy, w0, steps):
    """Run ``steps`` optimizer steps on ``energy(w)`` from ``w0``; returns the weights after each step."""
    w = torch.tensor(w0, dtype=torch.float64, requires_grad=True)
    opt = opt_factory([w])
    out = []
    for _ in range(steps):
        opt.zero_grad()
        energy(w).backward()
        opt.step()
        out.append(w.detach().clone().tolist())
    return out, opt, w


def _steps_with_grads(opt_factory, w0, grads):
    """Optimizer steps with the gradient set by hand each time; returns the weights after each step."""
    w = torch.tensor(w0, dtype=torch.float64, requires_grad=True)
    opt = opt_factory([w])
    out = []
    for g in grads:
        w.grad = torch.tensor(g, dtype=torch.float64)
        opt.step()
        out.append(w.detach().clone().tolist())
    return out, opt, w


# ----------------------------------------------------------------------------------- QuickProp
def test_quickprop_three_steps_by_hand():
    """E = 1/2 (w1 - 1)^2 + 2 (w2 + 1)^2 from (0, 0); lr = 0.1, mu = 1.75 (shrink = 1.75/2.75), no decay.

    step 1 (previous step 0): g = (-1, 4); dw = -0.1 g = (0.1, -0.4)                       -> (0.1, -0.4)
    step 2: g = (-0.9, 2.4)
      w1: dw_prev > 0, S < 0 -> add -lr S = 0.09; S = -0.9 < shrink * (-1) = -0.6364 -> mu branch:
          1.75 * 0.1 = 0.175 (the secant would be 0.9); dw = 0.265                         -> 0.365
      w2: dw_prev < 0, S > 0 -> add -0.24; S = 2.4 > shrink * 4 = 2.545? no -> secant
          2.4 / (4 - 2.4) * (-0.4) = -0.6; dw = -0.84                                       -> -1.24
    step 3: g = (-0.635, -0.96)
      w1: S < 0 -> add 0.0635; -0.635 < shrink * (-0.9) = -0.5727 -> mu: 1.75 * 0.265 = 0.46375;
          dw = 0.52725                                                                      -> 0.89225
      w2: dw_prev < 0 but S < 0 (the minimum was crossed): no gradient term (sign rule);
          -0.96 > shrink * 2.4 = 1.527? no -> secant -0.96 / (2.4 + 0.96) * (-0.84) = 0.24 -> -1.0 (exact)
    """
    ws, _, _ = _descend(
        lambda p: QuickProp(p, lr=0.1, mu=1.75, weight_decay=0.0),
        lambda w: 0.5 * (w[0] - 1) ** 2 + 2 * (w[1] + 1) ** 2,
        [0.0, 0.0],
        3,
    )
    expected = [[0.1, -0.4], [0.365, -1.24], [0.89225, -1.0]]
    for got, exp in zip(ws, expected):
        assert got == pytest.approx(exp, abs=1e-14)


def test_quickprop_weight_decay_is_folded_into_the_slope():
    """dE/dw = 0, w0 = 2, lr = 0.5, decay 0.01, mu = 1.75.

    step 1: S = 0 + 0.01 * 2 = 0.02; dw = -0.5 * 0.02 = -0.01                       -> 1.99
    step 2: S = 0.0199; dw_prev < 0, S > 0 -> add -0.00995; S > shrink * 0.02 = 0.012727 -> mu:
            1.75 * (-0.01) = -0.0175; dw = -0.02745                                  -> 1.96255
    """
    ws, opt, w = _steps_with_grads(lambda p: QuickProp(p, lr=0.5, mu=1.75, weight_decay=0.01), [2.0], [[0.0], [0.0]])
    assert ws[0] == pytest.approx([1.99], abs=1e-15)
    assert ws[1] == pytest.approx([1.96255], abs=1e-15)
    assert opt.state[w]["prev_slope"].tolist() == pytest.approx([0.0199], abs=1e-16)


def test_quickprop_equal_slopes_outside_the_mu_branch_pause_then_restart():
    """A hand-set state (dw_prev = +1, S_prev = +2) with S = +2: the secant is 2/0. The rule's own steps
    never reach this (each goes downhill on its slope); the guard makes the step 0 (Fahlman's program
    would step by infinity), and the next step, its previous step being 0, is gradient descent:
    dw = -0.5 * 2 = -1."""
    w = torch.tensor([3.0], dtype=torch.float64, requires_grad=True)
    opt = QuickProp([w], lr=0.5, mu=1.75, weight_decay=0.0)
    opt.state[w]["prev_step"] = torch.tensor([1.0], dtype=torch.float64)
    opt.state[w]["prev_slope"] = torch.tensor([2.0], dtype=torch.float64)
    w.grad = torch.tensor([2.0], dtype=torch.float64)
    opt.step()
    assert w.tolist() == [3.0]
    opt.step()
    assert w.tolist() == [2.0]


def test_quickprop_first_step_and_untouched_params():
    """The first step is -lr * S; a parameter without a gradient is left alone (torch convention)."""
    a = torch.tensor([1.0, -2.0], dtype=torch.float64, requires_grad=True)
    b = torch.tensor([5.0], dtype=torch.float64, requires_grad=True)
    opt = QuickProp([a, b], lr=0.25, weight_decay=0.0)
    a.grad = torch.tensor([4.0, -8.0], dtype=torch.float64)
    opt.step()
    assert a.tolist() == [0.0, 0.0] and b.tolist() == [5.0]


# ----------------------------------------------------------------------------------- Delta-Bar-Delta
def test_delta_bar_delta_three_steps_by_hand():
    """E = 1/2 (w1 - 1)^2 + 5 (w2 + 1)^2 from (0, 0); lr = 0.15, kappa = 0.05, phi = 0.4, theta = 0.5.

    step 1: d = (-1, 10); bar = 0 -> rates stay 0.15; bar = (-0.5, 5); dw = (0.15, -1.5)     -> (0.15, -1.5)
    step 2: d = (-0.85, -5)
      w1: bar * d > 0 -> eps = 0.15 + 0.05 = 0.2; bar = -0.675; dw = 0.17                    -> 0.32
      w2: bar * d < 0 -> eps = 0.15 * (1 - 0.4) = 0.09; bar = 0; dw = 0.45                   -> -1.05
    step 3: d = (-0.68, -0.5)
      w1: agree -> eps = 0.25; bar = -0.6775; dw = 0.17                                      -> 0.49
      w2: bar = 0 -> neither branch, eps stays 0.09; bar = -0.25; dw = 0.045                  -> -1.005
    """
    ws, opt, w = _descend(
        lambda p: DeltaBarDelta(p, lr=0.15, kappa=0.05, phi=0.4, theta=0.5),
        lambda w: 0.5 * (w[0] - 1) ** 2 + 5 * (w[1] + 1) ** 2,
        [0.0, 0.0],
        3,
    )
    expected = [[0.15, -1.5], [0.32, -1.05], [0.49, -1.005]]
    for got, exp in zip(ws, expected):
        assert got == pytest.approx(exp, abs=1e-14)
    assert opt.state[w]["eps"].tolist() == pytest.approx([0.25, 0.09], abs=1e-15)
    assert opt.state[w]["delta_bar"].tolist() == pytest.approx([-0.6775, -0.25], abs=1e-15)


def test_delta_bar_delta_momentum_by_hand():
    """E = 1/2 (w - 1)^2 from 0; lr = 0.1, kappa = 0.05, phi = 0.5, theta = 0.8, momentum 0.5.

    step 1: d = -1, eps 0.1, dw = 0.1; bar = 0.2 * (-1) = -0.2                              -> 0.1
    step 2: d = -0.9, agree -> eps 0.15; dw = 0.135 + 0.5 * 0.1 = 0.185;
            bar = 0.2 * (-0.9) + 0.8 * (-0.2) = -0.34                                       -> 0.285
    step 3: d = -0.715, agree -> eps 0.2; dw = 0.143 + 0.5 * 0.185 = 0.2355;
            bar = 0.2 * (-0.715) + 0.8 * (-0.34) = -0.415                                   -> 0.5205
    """
    ws, opt, w = _descend(
        lambda p: DeltaBarDelta(p, lr=0.1, kappa=0.05, phi=0.5, theta=0.8, momentum=0.5),
        lambda w: 0.5 * (w[0] - 1) ** 2,
        [0.0],
        3,
    )
    assert [v[0] for v in ws] == pytest.approx([0.1, 0.285, 0.5205], abs=1e-14)
    assert opt.state[w]["delta_bar"].tolist() == pytest.approx([-0.415], abs=1e-15)


# ----------------------------------------------------------------------------------- offset sigmoid
def test_offset_sigmoid_backward_adds_the_offset():
    """sigma'(0) = 0.25 and sigma'(+-ln 3) = 0.75 * 0.25 = 0.1875; with offset 0.1: 0.35 and 0.2875."""
    x = torch.tensor([0.0, math.log(3.0), -math.log(3.0)], dtype=torch.float64, requires_grad=True)
    y = offset_sigmoid(x, 0.1)
    assert torch.equal(y.detach(), torch.sigmoid(x.detach()))  # the forward pass is unchanged
    y.sum().backward()
    assert x.grad.tolist() == pytest.approx([0.35, 0.2875, 0.2875], abs=1e-15)


def test_offset_sigmoid_matches_a_second_formulation():
    """sigmoid(z) + offset * (z - z.detach()) has the same value and the gradient sigma' + offset."""
    z = torch.linspace(-8, 8, 41, dtype=torch.float64)
    w = torch.linspace(-1, 1, 41, dtype=torch.float64)
    for offset in (0.0, 0.1, 0.5):
        a = z.clone().requires_grad_(True)
        (offset_sigmoid(a, offset) * w).sum().backward()
        b = z.clone().requires_grad_(True)
        ((torch.sigmoid(b) + offset * (b - b.detach())) * w).sum().backward()
        torch.testing.assert_close(a.grad, b.grad, rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------------- parameters
@pytest.mark.parametrize(
    "factory, key, value",
    [
        (lambda p: QuickProp(p, lr=0.0), "lr", 0.0),
        (lambda p: QuickProp(p, lr=float("nan")), "lr", "nan"),
        (lambda p: QuickProp(p, mu=-1.0), "mu", -1.0),
        (lambda p: QuickProp(p, weight_decay=-1e-4), "weight_decay", -1e-4),
        (lambda p: QuickProp(p, mu="big"), "mu", "big"),
        (lambda p: DeltaBarDelta(p, kappa=-0.1), "kappa", -0.1),
        (lambda p: DeltaBarDelta(p, phi=1.0), "phi", 1.0),
        (lambda p: DeltaBarDelta(p, theta=1.5), "theta", 1.5),
        (lambda p: DeltaBarDelta(p, momentum=1.0), "momentum", 1.0),
        (lambda p: offset_sigmoid(p[0], -0.1), "sigmoid_prime_offset", -0.1),
    ],
)
def test_bad_parameters_name_key_value_and_range(factory, key, value):
    with pytest.raises(ConfigError) as err:
        factory([torch.zeros(2, dtype=torch.float64)])
    assert err.value.key == key and str(value) in str(err.value) and "expected" in str(err.value)


@pytest.mark.parametrize(
    "name, hparams, key",
    [
        ("quickprop", {"mu": 0.0}, "optim.mu"),
        ("delta_bar_delta", {"phi": -0.5}, "optim.phi"),
        ("rprop", {"eta_plus": 1.0}, "optim.eta_plus"),
        ("rprop", {"step_min": 1.0, "step_max": 0.5}, "optim.step_max"),
        ("adam", {"beta2": 1.0}, "optim.beta2"),
        ("sgd", {"momentum": 1.0}, "optim.momentum"),
        ("quickprop", {"kappa": 0.1}, "optim.kappa"),  # a key the optimizer does not use
        ("lbfgs", {}, "optim._target_"),  # an unknown optimizer
        ("torch.optim.LBFGS", {}, "optim._target_"),  # a known one that is not elementwise
        ("torch.optim.NAdam", {"kappa": 0.1}, "optim.kappa"),  # a key torch's class does not take
        ("torch.optim.NAdam", {"lr": -1.0}, "optim._target_"),  # a value torch's class refuses
    ],
)
def test_make_optimizer_errors_carry_the_config_key(name, hparams, key):
    with pytest.raises(ConfigError) as err:
        make_optimizer(name, [torch.zeros(1, dtype=torch.float64, requires_grad=True)], hparams)
    assert err.value.key == key


def test_make_optimizer_maps_flat_keys_and_skips_none():
    p = [torch.zeros(1, dtype=torch.float64, requires_grad=True)]
    rprop = make_optimizer(
        "rprop", p, {"lr": 0.2, "eta_minus": 0.4, "eta_plus": 1.3, "step_min": 0.0, "step_max": 9.0, "momentum": None}
    )
    assert type(rprop).__module__ == "selpres.engines.optim.rprop"
    assert isinstance(rprop, torch.optim.Rprop)
    g = rprop.param_groups[0]
    assert (g["lr"], g["etas"], g["step_sizes"]) == (0.2, (0.4, 1.3), (0.0, 9.0))
    adam = make_optimizer("adam", p, {"lr": 0.01, "beta1": 0.8, "beta2": 0.99, "eps": 1e-6})
    assert adam.param_groups[0]["betas"] == (0.8, 0.99) and adam.param_groups[0]["eps"] == 1e-6
    qp = make_optimizer("quickprop", p, {"lr": 0.3, "mu": 2.0, "weight_decay": 0.0})
    assert isinstance(qp, QuickProp) and qp.param_groups[0]["mu"] == 2.0
