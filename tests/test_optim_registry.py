"""The optimizer registry: built-ins are the modules of selpres/engines/optim (nothing else lists them), a user's
own is an import path, and every rule the engines accept is elementwise, so stepping the replicas' stacked weights
is stepping R separate optimizers."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from selpres.engines.optim import NOT_ELEMENTWISE, OPTIMIZERS, check_hparams, keywords, modes, optimizer_class
from selpres.engines.optim._replicas import ReplicaSteps
from selpres.errors import ConfigError

from conftest import REPO

BUILT_INS = ("adam", "adamw", "delta_bar_delta", "quickprop", "rprop", "sgd")
# torch's elementwise rules with keyword arguments that make every part of the rule run
ELEMENTWISE = [
    ("SGD", dict(lr=0.05, momentum=0.9, nesterov=True, weight_decay=0.01)),
    ("Adam", dict(lr=0.01, weight_decay=0.01, amsgrad=True)),
    ("AdamW", dict(lr=0.01)),
    ("NAdam", dict(lr=0.01, decoupled_weight_decay=True, weight_decay=0.01)),
    ("RAdam", dict(lr=0.01)),
    ("Adamax", dict(lr=0.01)),
    ("Adagrad", dict(lr=0.05, lr_decay=0.01)),
    ("Adadelta", dict(lr=0.5)),
    ("RMSprop", dict(lr=0.01, momentum=0.5, centered=True)),
    ("Rprop", dict(lr=0.01)),
    ("ASGD", dict(lr=0.01, t0=3)),
]


def test_built_ins_are_the_modules_and_each_exports_a_torch_optimizer():
    assert OPTIMIZERS.names == BUILT_INS
    for name in BUILT_INS:
        cls = optimizer_class(name)
        assert issubclass(cls, torch.optim.Optimizer) and cls.__module__ == f"selpres.engines.optim.{name}"
    assert modes("sgd") == ("online", "minibatch", "batch") and modes("quickprop") == ("batch",)
    assert modes("torch.optim.NAdam") == ("minibatch", "batch")
    assert OPTIMIZERS.path_of("torch.optim.NAdam") == "torch.optim.nadam.NAdam"


def test_checking_a_built_in_builds_no_optimizer():
    """The first torch.optim.Optimizer of a process imports torch._dynamo (~1.3 s); checks must not pay it."""
    code = (
        "import sys, torch\n"
        "from selpres.engines.optim import check_hparams\n"
        "for n in ('sgd', 'adam', 'adamw', 'rprop', 'quickprop', 'delta_bar_delta'): check_hparams(n, {'lr': 0.1})\n"
        "print('torch._dynamo' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_keys_are_checked_against_the_class():
    assert keywords(optimizer_class("adam"))[0] == ["lr", "beta1", "beta2", "eps", "weight_decay"]
    assert "momentum_decay" in keywords(optimizer_class("torch.optim.NAdam"))[0]
    with pytest.raises(
        ConfigError,
        match=r"optim.momentum=0.9 is not allowed: .*torch.optim.NAdam \(torch.optim.nadam.NAdam\) does not take it",
    ):
        check_hparams("torch.optim.NAdam", {"lr": 0.1, "momentum": 0.9})
    assert check_hparams("torch.optim.NAdam", {"lr": 0.1, "momentum_decay": 0.004}) == {
        "lr": 0.1,
        "momentum_decay": 0.004,
    }
    with pytest.raises(ConfigError, match=r"optim._target_='collections.OrderedDict' .*torch.optim.Optimizer"):
        optimizer_class("collections.OrderedDict")


@pytest.mark.parametrize("name", sorted(NOT_ELEMENTWISE))
def test_rules_that_look_across_weights_are_refused_by_name(name):
    if not hasattr(torch.optim, name):
        pytest.skip(f"this torch has no {name}")
    with pytest.raises(ConfigError, match=r"optim._target_=.* expected an elementwise rule"):
        optimizer_class(f"torch.optim.{name}")


def _grads(R, P, T, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(R, P, dtype=torch.float64, generator=g), [
        torch.randn(R, P, dtype=torch.float64, generator=g) for _ in range(T)
    ]


@pytest.mark.parametrize("name, kw", ELEMENTWISE, ids=[n for n, _ in ELEMENTWISE])
def test_an_elementwise_rule_on_stacked_replicas_is_r_separate_optimizers(name, kw):
    """Bit for bit: the same grads into one optimizer over [R, P] and into R optimizers over [P] each."""
    cls = getattr(torch.optim, name)
    R, P, T = 4, 23, 12
    w0, grads = _grads(R, P, T)
    stacked = w0.clone()
    opt = cls([stacked], **kw)
    rows = [w0[r].clone() for r in range(R)]
    opts = [cls([w], **kw) for w in rows]
    for g in grads:
        stacked.grad = g.clone()
        opt.step()
        for r in range(R):
            rows[r].grad = g[r].clone()
            opts[r].step()
    assert torch.equal(stacked, torch.stack(rows))
    # and a rule that is not elementwise is not: the test can fail
    if name == "SGD":
        norm = w0.clone()
        for g in grads:
            norm -= 0.05 * g / g.norm()  # a global-norm step
        sep = torch.stack([w0[r] - sum(0.05 * g[r] / g[r].norm() for g in grads) for r in range(R)])
        assert not torch.allclose(norm, sep)


@pytest.mark.parametrize("target", ["adam", "sgd", "torch.optim.NAdam"])
def test_replica_steps_with_masks_and_own_rates_are_r_separate_optimizers(target):
    """Pruning: a replica with nothing left does not step (weights, moments and step count kept) and each
    replica has its own learning rate; ReplicaSteps splits the stacked optimizer then, losslessly."""
    cls = optimizer_class(target)
    hp = {"lr": 0.01, "momentum": 0.9} if target == "sgd" else {"lr": 0.01}
    R, P, T = 3, 17, 10
    w0, grads = _grads(R, P, T, seed=1)
    flat = w0.clone()
    flat.grad = torch.zeros_like(flat)
    steps = ReplicaSteps(lambda params: cls(params, **hp), flat)
    rows = [w0[r].clone() for r in range(R)]
    opts = [cls([w], **hp) for w in rows]
    g = torch.Generator().manual_seed(2)
    for t, grad in enumerate(grads):
        uniform = t < 4
        active = None if uniform else torch.rand(R, generator=g) < 0.6
        lr = (
            torch.full((R,), 0.01, dtype=torch.float64)
            if uniform
            else 0.01 * torch.rand(R, generator=g, dtype=torch.float64)
        )
        flat.grad.copy_(grad)
        steps.step(lr, active)
        for r in range(R):
            if active is None or active[r]:
                opts[r].param_groups[0]["lr"] = float(lr[r])
                rows[r].grad = grad[r].clone()
                opts[r].step()
        assert (steps.rows is None) == uniform
    assert torch.equal(flat, torch.stack(rows))
    resumed = ReplicaSteps(lambda params: cls(params, **hp), flat.clone())
    resumed.load_state_dict(steps.state_dict())
    assert resumed.rows is not None and len(resumed.opt.state) == R
