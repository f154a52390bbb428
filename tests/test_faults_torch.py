"""Issue 39.2, checked against torch itself (2.13): how ``torch.save`` reports a write the disk refuses, and that
:func:`selpres.storage.atomic_write` turns it into an OSError naming the file with the fault's errno wherever in the
file the disk fills (the fault-injection layer: tests/test_faults.py)."""

from __future__ import annotations

import contextlib
import errno
import resource

import pytest
import torch
from test_faults import CODES, Disk, _is


# ----------------------------------------------------------------- torch's own report of a failed write
def test_torch_reports_a_full_disk_as_a_runtime_error_and_atomic_write_names_the_file_and_errno(tmp_path):
    """What torch 2.13 does (checked here, not assumed): ``torch.save`` into a file whose write fails with ENOSPC
    raises RuntimeError (``unexpected pos``), the OSError its ``__context__``; atomic_write raises an OSError naming
    the file with ENOSPC, torch's error as its cause, and leaves no file under either name."""
    from selpres.storage import atomic_write

    big = {"w": torch.zeros(10_000, dtype=torch.float64)}  # 80 KB: written past the buffer, inside torch's writer
    with Disk("ENOSPC", _is("direct.pt")).mounted():
        f = open(tmp_path / "direct.pt", "wb")
        with pytest.raises(RuntimeError, match=r"unexpected pos") as raw:
            torch.save(big, f)
        with contextlib.suppress(OSError):  # the buffer's rest cannot be written either
            f.close()
    assert isinstance(raw.value.__context__, OSError) and raw.value.__context__.errno == errno.ENOSPC
    with Disk("ENOSPC", _is("w.pt")).mounted(), pytest.raises(OSError) as named:
        atomic_write(tmp_path / "w.pt", lambda f: torch.save(big, f))
    assert (named.value.errno, named.value.filename) == (errno.ENOSPC, str(tmp_path / "w.pt"))
    chain, seen = [], named.value
    while seen is not None:
        chain.append(seen)
        seen = seen.__cause__ or seen.__context__
    assert any(isinstance(e, RuntimeError) and "unexpected pos" in str(e) for e in chain)  # torch's, behind it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["direct.pt"]  # torch's own, cut; none of atomic_write's


@pytest.mark.parametrize("fault", ["ENOSPC", "EDQUOT", "EFBIG"])
def test_wherever_the_disk_fills_during_torch_save_the_write_fails_as_an_oserror_naming_the_file(tmp_path, fault):
    """A 20 KB weights file (16 replicas of 6-13-2) cut at every 256th byte: each time an OSError naming the file with
    the fault's errno, nothing under the file's name and no temp file; where the cut falls decides whether torch
    reports it as its RuntimeError or the file's close as the OSError, and both must occur here."""
    from selpres.run.checkpoint import dumps
    from selpres.storage import atomic_write

    g = torch.Generator().manual_seed(0)
    obj = {"params": [torch.randn(16, *s, generator=g, dtype=torch.float64) for s in ((13, 6), (13,), (2, 13), (2,))]}
    path, behind = tmp_path / "weights.pt", set()
    size = len(dumps(obj))  # the bytes torch.save writes
    for budget in range(0, size, 256):
        with Disk(fault, _is("weights.pt"), 0, budget).mounted(), pytest.raises(OSError) as failed:
            atomic_write(path, lambda f: torch.save(obj, f))
        assert (failed.value.errno, failed.value.filename) == (CODES[fault], str(path)), budget
        assert list(tmp_path.iterdir()) == [], budget
        chain, e = [], failed.value.__cause__
        while e is not None:
            chain.append(e)
            e = e.__context__
        behind.add(type(chain[0]).__name__)
    assert behind == {"RuntimeError", "OSError"}


def test_torch_writing_by_path_under_a_file_size_limit_is_an_io_error_naming_the_file(tmp_path):
    """torch's C++ file stream (``torch.save(obj, "path")``) sets no errno: its RuntimeError ("PytorchStreamWriter
    failed writing file ... file write failed" or "unexpected pos") carries no OSError; selpres reads it as EIO
    (here under a real RLIMIT_FSIZE)."""
    from selpres.storage import write_failure

    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (4096, hard))
    try:
        with pytest.raises(RuntimeError) as raw:
            torch.save({"w": torch.zeros(10_000)}, str(tmp_path / "p.pt"))
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    failure = write_failure(raw.value)
    assert failure is not None and failure.errno == errno.EIO and "torch could not write it" in failure.strerror
    assert "\n" not in failure.strerror
    assert write_failure(RuntimeError("a bug, not a write")) is None and write_failure(ValueError("x")) is None
