"""Kept only for ``selpres.studies.modern``'s import of :func:`optim_target`, which now lives in
:mod:`selpres.report.groups`: the families of settings are the paper's studies' (``selpres.studies._families``).
Remove once modern imports ``optim_target`` from ``selpres.report.groups``."""

from selpres.report.groups import optim_target

__all__ = ["optim_target"]
