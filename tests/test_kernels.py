"""The native kernel's build, cache and loading: a real C file, and no crash or silent loss on bad caches."""

from __future__ import annotations

import re

import pytest
from conftest import requires_native

from selpres import _kernels

SIZES = (5, 3, 2)  # a topology no other test loads: its library is mapped only by the tests below


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """An empty kernel cache and an empty in-process memo, so each test builds and loads for itself."""
    monkeypatch.setenv("SELPRES_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(_kernels, "_kernels", {})
    return tmp_path / "cache"


def test_kernel_source_is_a_c_file_shipped_with_the_package():
    assert _kernels.SOURCE.name == "sgd.c" and _kernels.SOURCE.parent.name == "kernels"
    text = _kernels.SOURCE.read_text()
    assert "int selpres_train(" in text and "@" not in text  # no text-substitution placeholders left
    assert _kernels.macros((6, 13, 2)) == ["-DNL=2", "-DSIZES=6,13,2", "-DP_TOTAL=119", "-DTOT_UNITS=21",
                                           "-DMAXW=13", f"-DNI={_kernels.INTERLEAVE}"]  # P = (13*6 + 13) + (2*13 + 2)


@requires_native
def test_compiler_errors_point_at_real_lines_of_the_source(fresh_cache, monkeypatch):
    """Without its macros the file stops at its own #error; the message names sgd.c and that line."""
    monkeypatch.setattr(_kernels, "macros", lambda sizes: ["-DNL=1"])
    line = next(i for i, ln in enumerate(_kernels.SOURCE.read_text().splitlines(), 1)
                if ln.startswith("#error") and "-DNL" in ln)
    with pytest.raises(_kernels.KernelUnavailable) as info:
        _kernels.build(SIZES)
    assert re.search(rf"sgd\.c:{line}:", str(info.value)), str(info.value)
