"""selpres: selective presentation — train a back-propagation network on a growing training set
A1 ⊂ A2 ⊂ … ⊂ A_{p+1} = U, and find out honestly whether it pays.

The public API is the names in ``__all__``, and the report's blocks a study is made of (``selpres.report.__all__``);
everything else is internal and may move. The package's rooms follow the data's flow (``docs/architecture.md``)::

    arms -> data -> presentation -> engines -> run -> report

The studies and the benchmarks are apart from the library, the repository's ``studies/`` (not in this package).

Names are imported on first use (PEP 562), so ``import selpres`` costs nothing until one is asked for and the
command line starts without torch where it does not need it (``python train.py --help``).
"""

from __future__ import annotations

import importlib

# name -> the module that owns it
_EXPORTS = {
    # the method in any PyTorch loop: the Sampler (DDP-aware) and its Lightning callback (imports lightning)
    "SelectivePresentation": "selpres.presentation.sampler",
    "SelectivePresentationWarning": "selpres.presentation.sampler",
    "SelectivePresentationCallback": "selpres.presentation.lightning",
    # schedules of nested training sets and the priority orders whose prefixes are the A_i
    "Schedule": "selpres.presentation.schedule",
    "build_schedule": "selpres.presentation.schedule",
    "priority_order": "selpres.presentation.orders",
    # arms: the paper's two-link arm (eq. 6), any serial chain (eq. 4-5), URDF files in and out
    "TwoLinkArm": "selpres.arms.two_link",
    "SerialArm": "selpres.arms.serial",
    "make_arm": "selpres.arms.sources",
    "load_urdf": "selpres.arms.urdf",
    "to_urdf": "selpres.arms.urdf",
    # data: a config's task (exemplar set, test sets, scaler; from specs or a job's recorded nodes), exported files
    # read back; the scaler is the foundation's (selpres.patterns)
    "load_task": "selpres.data.task",
    "load_exported": "selpres.data.export",
    "load_csv": "selpres.data.export",
    "Scaler": "selpres.patterns",
    # the network, to use what a job trained (weights.pt)
    "BPN": "selpres.engines.model",
    "load_into": "selpres.engines.model",
    # a method of one's own (docs/extending.md): what decides each epoch's patterns, and what it is charged
    "Selector": "selpres.presentation.selector",
    "Presentation": "selpres.presentation.selector",
    "Ledger": "selpres.presentation.selector",
    # the report of a sweep's job folders (what selpres-report writes)
    "write_report": "selpres.report.build",
    # errors a caller may catch
    "ConfigError": "selpres.errors",
    "FileError": "selpres.errors",
}

__all__ = sorted(_EXPORTS)

# the command line's internals, public before issue 25: still in their modules, named there by the error below
_INTERNAL = {
    "train": "selpres.run.train",  # the job's loop on a composed config (selpres-train runs it)
    "compose_train": "selpres.run.config",  # the config as selpres-train composes it (needs the package's configs)
}


def __getattr__(name: str):
    if name in _INTERNAL:
        raise AttributeError(
            f"selpres.{name} is the command line's, not the public API (selpres.__all__): "
            f"from {_INTERNAL[name]} import {name}"
        )
    if name not in _EXPORTS:
        raise AttributeError(f"module 'selpres' has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value  # once imported, a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
