"""``data.kind: file`` (``data=file``): the user's table (``selpres.data.file``), split into exemplar and held-out
rows by ``data.test_seed``; the 10-pattern test set takes ``test_from_exemplar`` rows of the exemplar set and the
rest from the held-out rows. The file is what the task is read from (``reads_files``)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path

import torch

from selpres.data import file as F
from selpres.data import paper as D
from selpres.data.routes import DataRoute
from selpres.data.spec import DataSpec
from selpres.data.task import Shape, Task
from selpres.patterns import ExemplarSet, Patterns, TestSets
from selpres.registry import Choice
from selpres.seeding import derive_seed

log = logging.getLogger("selpres")


class File(DataRoute):
    @dataclass
    class Keys:
        path: str  # a CSV with a header row, or an .npz
        inputs: list[str]  # the columns the network reads, in this order
        outputs: list[str]  # the columns it predicts

    USES_ARM = False

    def reads_files(self, data: DataSpec) -> list[Path]:
        return [Path(data.path).expanduser()] if isinstance(data.path, str) else []

    def shape(self, robot: Choice, data: DataSpec) -> Shape:
        ins, outs = F.check_columns(data.path, data.inputs, data.outputs)
        return Shape(ins, outs, f"data=file ({data.path})")

    def build(self, robot: Choice, data_cfg: DataSpec) -> Task:
        path = data_cfg.path
        ins, outs = F.check_columns(path, data_cfg.inputs, data_cfg.outputs)
        table = F.load_columns(path, [*ins, *outs])
        sc = data_cfg.scaling
        squeezed = F.check_ranges(
            path, [*ins, *outs], table, len(outs), *(float(sc[k]) for k in ("margin", "lo", "hi"))
        )
        for w in squeezed:
            log.warning("%s", w)
        rows = table.shape[0]
        held_n = D.heldout_count(data_cfg.heldout, rows, f"the {rows} rows of {path}")
        n_test, n_ex = int(data_cfg.test_patterns), int(data_cfg.test_from_exemplar)
        if rows - held_n < max(1, n_ex) or held_n < n_test - n_ex:
            raise F.DataFileError(
                path,
                "rows",
                f"{rows:,}: too few to hold out data.heldout={data_cfg.heldout} "
                f"({held_n} rows, at least {n_test - n_ex} for the test patterns) and train on "
                f"the rest (at least {max(1, n_ex)} rows)",
            )
        perm = torch.randperm(
            rows, generator=torch.Generator().manual_seed(derive_seed(int(data_cfg.test_seed), "split"))
        )
        held, train = perm[:held_n].sort().values, perm[held_n:].sort().values
        X, Y = table[:, : len(ins)], table[:, len(ins) :]
        exemplar = ExemplarSet(X[train].contiguous(), Y[train].contiguous(), n_candidates=rows)
        n = len(exemplar)
        gen = torch.Generator().manual_seed(int(data_cfg.test_seed))
        idx_ex = torch.randperm(n, generator=gen)[:n_ex]
        idx_out = held[torch.randperm(held_n, generator=gen)[: n_test - n_ex]]
        test10 = Patterns(torch.cat((exemplar.X[idx_ex], X[idx_out])), torch.cat((exemplar.Y[idx_ex], Y[idx_out])))
        tests = TestSets(test10, torch.arange(n_test) < n_ex, Patterns(X[held].contiguous(), Y[held].contiguous()))
        info = {
            "kind": "file",
            "source": f"data=file {path}",
            "path": str(path),
            "sha256": F.file_digest(path),
            "rows": rows,
            "heldout": held_n,
            "n": n,
            "inputs": list(ins),
            "outputs": list(outs),
            "warnings": squeezed,  # columns an outlier collapses (selpres.data.file.check_ranges)
        }
        task = Task(exemplar, tests, None, ins, outs, info)
        return replace(task, scaler=task.fit_scaler(data_cfg))


ROUTE = File
