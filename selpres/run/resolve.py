"""One resolved job: the composed config read once and checked once, into the plain typed specs the rooms receive.

:func:`resolve` is the first step of every job (``selpres.run.train.train``): it reads the config into plain values
once (``selpres.run.specs.plain``), refuses a key no code reads and a number that is not finite, makes each node's
spec (``selpres.run.specs.read``: the robot, the data, the schedule, the optimizer, the engine), and runs every check
a type cannot express (``selpres.run.checks``, with the optimizer's of ``selpres.run.optimizer`` and the estimates of
``selpres.run.estimate``) before anything is built or written: one ConfigError naming the key, the value and what is
allowed. What comes back, a :class:`~selpres.run.specs.JobSpec`, is all the loop, the results and TensorBoard read
of the job; no room below ``run`` sees the config, and nothing after this function reads it again.
"""

from __future__ import annotations

from typing import Any

from selpres.engines.factory import mode_of
from selpres.run import checks
from selpres.run.specs import JobSpec, engine_spec, optim_spec, plain, read


def resolve(cfg: Any) -> JobSpec:
    """The composed ``train`` config (or its plain values) as a checked job; raises ConfigError, writes nothing. The
    checks that need the exemplar set (stage sizes against n, a data file's cells) follow in
    ``selpres.run.problem.prepare``, still before anything is written."""
    c = plain(cfg)  # the one read of the composed config
    checks.check_plain(c)  # a key no code reads (+schedule.p=1), a number that is not finite
    job = read(c)
    return job.checked(checks.check(job))


def engine_kind(cfg: Any) -> str:
    """The update a config's job runs (selpres.engines.factory's mode: ``online``, ``minibatch`` or ``batch``), read
    from its optim node, hidden units and engine alone: a finished job whose results.json names an engine of another
    mode is another update's, and is run again (``selpres.run.folder.finished``)."""
    c = plain({"optim": cfg.optim, "activation": cfg.model.activation, "engine": cfg.engine})
    return engine_spec(optim_spec(c["optim"]), c["activation"], c["engine"]).mode


def kind_of(engine_name: str | None) -> str:
    """:func:`engine_kind` of an engine that ran (results.json ``engine``; records older than it name none)."""
    return mode_of(engine_name)
