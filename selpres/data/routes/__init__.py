"""Data routes: how a task's exemplar and test sets are made, one module each (a registry, ``ROUTES``, by
``data.kind``): ``grid`` (the paper's section 5.1), ``sampled`` (drawn for any arm), ``file`` (the user's table).

A route module exports ``ROUTE``, a class with ``KEYS`` (the ``DataSpec`` keys it reads; a composed config's
other kinds' keys must stay unset), ``USES_ARM`` (whether the robot node matters), ``shape(robot, data)`` (the
network's inputs and outputs, no data made), ``build(robot, data)`` (the ``selpres.data.task.Task``) and
``reads_files(data)`` (the files the data is read from: their stamps key the task, which is then never stored).
"""

from __future__ import annotations

from pathlib import Path

from selpres.registry import Registry

ROUTES = Registry("data.kind", "selpres.data.routes", "ROUTE")


class DataRoute:
    KEYS: tuple[str, ...] = ()
    USES_ARM = True

    def reads_files(self, data) -> list[Path]:
        return []
