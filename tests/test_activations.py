"""Hidden units by registry: the built-ins are the modules of selpres/engines/activations, each derivative
checked against autograd; a user's own class runs by its import path; a name that is neither is refused."""

from __future__ import annotations

import pytest
import torch

from selpres.engines.activations import ACTIVATIONS, activation
from selpres.engines.minibatch import MiniBatchEngine
from selpres.engines.model import BPN, init_replica_params, load_into
from selpres.errors import ConfigError


class Softplus:
    """A user's own unit, defined outside the package (here: in this test module)."""

    @staticmethod
    def forward(z):
        return torch.nn.functional.softplus(z)

    @staticmethod
    def prime(z, a):
        return torch.sigmoid(z)


def test_built_ins_are_the_modules_and_each_derivative_is_autograds():
    assert ACTIVATIONS.names == ("leaky_relu", "relu", "sigmoid", "silu", "tanh")
    z = torch.linspace(-4, 4, 81, dtype=torch.float64).add(0.013).requires_grad_(True)
    for name in (*ACTIVATIONS.names, f"{__name__}.Softplus"):
        act = activation(name)
        a = act.forward(z)
        (want,) = torch.autograd.grad(a.sum(), z)
        torch.testing.assert_close(act.prime(z.detach(), a.detach()), want, rtol=0, atol=1e-15)


def test_unknown_and_unfit_units_are_refused_naming_the_key():
    with pytest.raises(
        ConfigError, match=r"model.activation='gelu' is not allowed: expected one of leaky_relu, relu, sigmoid"
    ):
        activation("gelu")
    with pytest.raises(ConfigError, match=r"model.activation='collections.OrderedDict'.*forward\(z\) and prime"):
        activation("collections.OrderedDict")


def test_a_users_unit_trains_on_the_minibatch_engine_as_autograd_does():
    sizes, path = (6, 5, 2), f"{__name__}.Softplus"
    params = init_replica_params(sizes, [3, 4])
    X, Y = torch.rand(8, 6, dtype=torch.float64), torch.rand(8, 2, dtype=torch.float64)
    eng = MiniBatchEngine(sizes, params, "sgd", {"lr": 0.1, "momentum": 0.0}, 8, path)
    eng.train_epoch(X, Y, torch.arange(8).repeat(2, 1))
    for r in range(2):
        model = load_into(BPN(sizes, activation=path), params, r)
        torch.nn.functional.mse_loss(model(X), Y).backward()
        with torch.no_grad():
            want = [p - 0.1 * p.grad for p in model.flat_params()]
        for got, w in zip(eng.params(), want):
            torch.testing.assert_close(got[r], w, rtol=0, atol=1e-14)
