"""The native kernel's build, cache and loading: a real C file, and no crash or silent loss on bad caches."""

from __future__ import annotations

import hashlib
import logging
import os
import re
import resource
import subprocess
import sys
import textwrap

import pytest
import torch

from selpres.native import KernelUnavailable, build, cpu_flags, library, load, sgd

from conftest import REPO, requires_native

SIZES = (5, 3, 2)  # a topology no other test loads: its library is mapped only by the tests below


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """An empty kernel cache and an empty in-process memo, so each test builds and loads for itself."""
    monkeypatch.setenv("SELPRES_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(build, "_loaded", {})
    return tmp_path / "cache"


def test_kernel_source_is_a_c_file_shipped_with_the_package():
    assert sgd.SOURCE.name == "sgd.c" and sgd.SOURCE.parent.name == "kernels"
    text = sgd.SOURCE.read_text()
    assert "int selpres_train(" in text and "@" not in text  # no text-substitution placeholders left
    # P = (13*6 + 13) + (2*13 + 2), units 6 + 13 + 2
    assert sgd.macros((6, 13, 2)) == [
        "-DNL=2",
        "-DSIZES=6,13,2",
        "-DP_TOTAL=119",
        "-DTOT_UNITS=21",
        "-DMAXW=13",
        f"-DNI={sgd.INTERLEAVE}",
    ]


@requires_native
def test_compiler_errors_point_at_real_lines_of_the_source(fresh_cache, monkeypatch):
    """Without its macros the file stops at its own #error; the message names sgd.c and that line."""
    monkeypatch.setattr(sgd, "macros", lambda sizes: ["-DNL=1"])
    line = next(
        i for i, ln in enumerate(sgd.SOURCE.read_text().splitlines(), 1) if ln.startswith("#error") and "-DNL" in ln
    )
    with pytest.raises(KernelUnavailable) as info:
        sgd.build(SIZES)
    assert re.search(rf"sgd\.c:{line}:", str(info.value)), str(info.value)


# ---------------------------------------------------------------- a bad cache never crashes; failures retried
@requires_native
@pytest.mark.slow  # builds the kernel afresh
@pytest.mark.parametrize("damage", ["truncate", "flip"])
def test_damaged_cached_library_is_rebuilt_not_loaded(fresh_cache, damage, caplog):
    path = sgd.build(SIZES)
    good = path.read_bytes()
    if damage == "truncate":  # e.g. a full disk, or a copy killed half way
        path.write_bytes(good[: len(good) // 2])
    else:  # same length, one byte changed in the middle of the code
        bad = bytearray(good)
        bad[len(bad) // 2] ^= 0xFF
        path.write_bytes(bytes(bad))
    with caplog.at_level(logging.WARNING, logger="selpres"):
        kernel = load(SIZES)
    assert kernel.path == path and path.read_bytes() == good
    assert any("fails its checksum" in r.getMessage() for r in caplog.records)


@requires_native
@pytest.mark.slow  # builds the kernel afresh
def test_library_without_checksum_is_rebuilt(fresh_cache):
    """A library whose sidecar is missing was not finished (or predates the checksum): rebuilt."""
    path = sgd.build(SIZES)
    assert build._sidecar(path).read_text().strip() == hashlib.sha256(path.read_bytes()).hexdigest()
    build._sidecar(path).unlink()
    path.write_bytes(b"\x7fELF not a library")
    assert load(SIZES).path == path and build._sidecar(path).exists()


@requires_native
def test_cpu_without_avx2_never_opens_a_cached_library(fresh_cache, monkeypatch):
    sgd.build(SIZES)  # a library is in the cache (as if built by another machine of a cluster)
    opened = []
    monkeypatch.setattr(library.ctypes, "CDLL", lambda *a, **k: opened.append(a) or pytest.fail("opened"))
    monkeypatch.setattr(build, "cpu_flags", lambda: frozenset({"sse2", "avx", "fma"}))
    with pytest.raises(KernelUnavailable, match="no AVX2/FMA: this CPU lacks avx2"):
        load(SIZES)
    assert opened == []


def test_cpu_check_names_what_is_missing():
    build.check_cpu(frozenset({"avx2", "fma", "sse2"}))  # passes
    with pytest.raises(KernelUnavailable, match=r"lacks avx2, fma \(no CPU flags readable"):
        build.check_cpu(frozenset())
    with pytest.raises(KernelUnavailable, match=r"lacks fma$"):
        build.check_cpu(frozenset({"avx2"}))


def test_cpu_flags_are_those_every_core_lists(monkeypatch, tmp_path):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text("processor\t: 0\nflags\t\t: fpu sse2 avx2 fma\n\nprocessor\t: 1\nflags\t\t: fpu sse2 fma\n")
    real_open = open

    def fake_open(f, *a, **k):
        return real_open(cpuinfo if f == "/proc/cpuinfo" else f, *a, **k)

    monkeypatch.setattr("builtins.open", fake_open)
    assert cpu_flags() == frozenset({"fpu", "sse2", "fma"})


@requires_native
@pytest.mark.slow  # builds the kernel afresh
def test_failed_build_is_reported_then_retried(fresh_cache, monkeypatch):
    """A compiler failure or a time-out is not remembered for the process: the next load() builds."""
    cc = os.environ.get("CC")
    monkeypatch.setenv("CC", "false")
    with pytest.raises(KernelUnavailable, match="'false' does not run|false exited with 1"):
        load(SIZES)
    monkeypatch.setenv("CC", cc) if cc else monkeypatch.delenv("CC")
    monkeypatch.setattr(build, "COMPILE_TIMEOUT", 1e-4)
    with pytest.raises(KernelUnavailable, match="timed out after 0.0001 s"):
        load(SIZES)
    assert not list(fresh_cache.glob("*.so"))  # nothing half-built left behind
    monkeypatch.setattr(build, "COMPILE_TIMEOUT", 300)
    assert load(SIZES).path.exists()


# ---------------------------------------------------------------- large topologies
@pytest.mark.slow
@requires_native
def test_wide_layer_does_not_overflow_the_stack(tmp_path):
    """6-40000-2: ~7.7 MB of activations and deltas (the old kernel kept them on the stack), more than a
    2 MB stack holds. Run in a child process with that stack limit (what a small thread stack would be),
    so a crash fails this test instead of killing pytest."""
    code = textwrap.dedent("""
        import torch
        from selpres.engines.factory import EngineSpec, build_engine
        from selpres.engines.model import init_replica_params
        sizes = (6, 40000, 2)
        g = torch.Generator().manual_seed(0)
        X = torch.rand(5, 6, generator=g, dtype=torch.float64)
        Y = 0.1 + 0.8 * torch.rand(5, 2, generator=g, dtype=torch.float64)
        params = init_replica_params(sizes, [0])
        order = torch.tensor([[3, 1, 4, 0, 2]])
        out = []
        for name in ("native", "reference"):
            eng = build_engine(EngineSpec.online(name, sizes, 0.15, 0.9, 1, threads=1), params)
            out.append((eng.train_epoch(X, Y, order), eng.params()))
        (la, pa), (lb, pb) = out
        assert (la - lb).abs().max() <= 1e-12, (la, lb)
        assert max((a - b).abs().max().item() for a, b in zip(pa, pb)) <= 1e-12
        print("ok")
    """)
    env = dict(os.environ, SELPRES_CACHE_DIR=str(tmp_path), PYTHONPATH=str(REPO))

    def two_mb_stack():
        hard = resource.getrlimit(resource.RLIMIT_STACK)[1]
        soft = 2 << 20 if hard == resource.RLIM_INFINITY else min(hard, 2 << 20)
        resource.setrlimit(resource.RLIMIT_STACK, (soft, hard))

    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600, preexec_fn=two_mb_stack
    )
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", (proc.returncode, proc.stderr[-2000:])


# ---------------------------------------------------------------- small work stays in the calling thread
def test_threads_for_gives_a_thread_only_work_worth_one():
    M, threads_for = library.MIN_THREAD_WORK, sgd.Kernel.threads_for
    assert [threads_for(w, 2) for w in (0, 1, M, 2 * M - 1)] == [1, 1, 1, 1]
    assert [threads_for(w, 2) for w in (2 * M, 10**12)] == [2, 2]
    assert threads_for(10**12, 1) == 1 and threads_for(3 * M, 8) == 3 and threads_for(10**12, 8) == 8


@requires_native
def test_small_calls_never_touch_the_pool_and_large_ones_do(monkeypatch):
    """R = 1 on the 10 test patterns (the curve's every-epoch call) and a small epoch run in the calling
    thread; the same calls with MIN_THREAD_WORK = 1 go to the pool, with bitwise the same numbers."""
    import torch

    from selpres.engines.model import init_replica_params

    from conftest import online_engine

    sizes = (6, 13, 2)
    g = torch.Generator().manual_seed(0)
    X = torch.rand(50, 6, generator=g, dtype=torch.float64)
    Y = torch.rand(50, 2, generator=g, dtype=torch.float64)
    order = torch.stack([torch.randperm(50, generator=g) for _ in range(5)])
    real = sgd.Kernel._executor
    pooled = []
    monkeypatch.setattr(sgd.Kernel, "_executor", lambda self, n: pooled.append(n) or real(self, n))
    results = []
    for min_work in (library.MIN_THREAD_WORK, 1):
        monkeypatch.setattr(library, "MIN_THREAD_WORK", min_work)
        one, five = (
            online_engine("native", sizes, init_replica_params(sizes, list(range(R))), 0.15, 0.9, 1, threads=2)
            for R in (1, 5)
        )
        small = [one.predict(X[:10]), one.squared_errors(X[:10], Y[:10]), five.train_epoch(X, Y, order)]
        results.append([*small, *five.params(), five.predict(X), five.squared_errors(X, Y)])
        # forced: R = 1's predict splits its 10 patterns, R = 5's calls their 2 groups; R = 1's squared
        # errors stay whole (one group, one block of patterns: nothing to split)
        assert pooled == ([] if min_work > 1 else [2] * 4), pooled
    assert all(torch.equal(a, b) for a, b in zip(*results))


# -------------------------------------------------------- evaluation at 8 lanes (AVX-512) = at 4 lanes (AVX2)
AVX2_ONLY = ("-mno-avx512f",)  # after -march=native: the same source, evaluated at 4 lanes only
requires_avx512 = pytest.mark.skipif(
    "avx512f" not in cpu_flags(), reason="this CPU lacks avx512f: evaluation runs at 4 lanes only"
)


def _bits(t):
    """The float64s' bit patterns: equal means bitwise equal, NaNs (and their payloads) included."""
    return t.contiguous().view(torch.int64)


def _packed_weights(sizes, G, seed):
    """[G, P, 4] weights of G groups: most lanes N(0, 1); lane 0 of every group x1000, its first and last
    output biases -1e4 and 1e4, so its sigmoids saturate and exp's clamp at -708/708 is reached; one NaN
    weight in replica 6 (the upper half of the first pair of groups), or replica 1 when there is one group."""
    P = sum(o * i + o for i, o in zip(sizes[:-1], sizes[1:]))
    g = torch.Generator().manual_seed(seed)
    w = torch.randn(G, P, 4, generator=g, dtype=torch.float64)
    w[:, :, 0] *= 1000.0
    w[:, P - sizes[-1], 0], w[:, P - 1, 0] = -1e4, 1e4  # output biases: sigmoid(-708) = 3.3e-308, and 1.0
    nan_replica = 6 if G > 1 else 1
    w[nan_replica // 4, P // 2, nan_replica % 4] = float("nan")
    return w, nan_replica


@requires_native
@requires_avx512
@pytest.mark.parametrize("sizes", [(6, 13, 2), (6, 5, 5, 2), (18, 40, 6)])
def test_avx512_evaluation_is_bitwise_the_avx2_one(monkeypatch, sizes):
    """forward and squared_errors of the AVX-512 build (pairs of groups in a zmm, a leftover odd group at 4
    lanes) against the AVX2-only build of the same source, bit for bit: odd and even group counts, chunks
    that start at an odd group, N = 1037 (two score blocks, the second 13 patterns: one batch of NPAT = 8
    and 5 leftovers), a NaN replica, saturated sigmoids. 1 and 2 threads (MIN_THREAD_WORK = 1, so even
    these small calls are split: groups, or patterns/blocks when there is one group)."""
    wide, narrow = load(sizes), load(sizes, AVX2_ONLY)
    assert (wide.eval_lanes, narrow.eval_lanes) == (8, 4)
    monkeypatch.setattr(library, "MIN_THREAD_WORK", 1)
    g = torch.Generator().manual_seed(len(sizes))
    N = sgd.SCORE_BLOCK + 13
    X = torch.rand(N, sizes[0], generator=g, dtype=torch.float64)
    Y = 0.1 + 0.8 * torch.rand(N, sizes[-1], generator=g, dtype=torch.float64)
    for R in (4, 8, 12, 20):
        w, nan_replica = _packed_weights(sizes, R // 4, seed=R)
        for threads in (1, 2):
            for method, args in (("forward", (X,)), ("squared_errors", (X, Y))):
                got = getattr(wide, method)(sizes, w, *args, threads)
                want = getattr(narrow, method)(sizes, w, *args, threads)
                assert torch.equal(_bits(got), _bits(want)), (sizes, R, threads, method)
                nan_rows = got.isnan().flatten(1).any(1).nonzero().flatten().tolist()
                assert nan_rows == [nan_replica], (sizes, R, threads, method, nan_rows)
        outputs = wide.forward(sizes, w, X, 1)  # the data reach exp's clamp (sigmoid(-708) ~ 3.3e-308), 1.0
        outputs = outputs[~outputs.isnan()]
        assert outputs.min() < 1e-300 and outputs.max() == 1.0, (sizes, R, outputs.min(), outputs.max())


def test_eval_lanes_say_what_the_build_runs():
    """8 where the compiler targets AVX-512F (-march=native on a CPU that has it), else 4; the AVX2-only
    variant is a second library beside the usual one, never a replacement."""
    try:
        usual, avx2 = load(SIZES), load(SIZES, AVX2_ONLY)
    except KernelUnavailable as exc:
        pytest.skip(f"native kernel unavailable: {exc}")
    assert usual.eval_lanes == (8 if "avx512f" in cpu_flags() else 4)
    assert avx2.eval_lanes == 4 and avx2.path != usual.path and load(SIZES) is usual


def test_extra_flags_and_included_headers_key_the_cache(tmp_path):
    """A library is keyed by its extra flags and by the headers its source includes (eval.h): an edited
    header must never reuse a library built from the old one."""
    src = tmp_path / "sgd.c"
    src.write_text(sgd.SOURCE.read_text())
    for name in re.findall(r'#include "([^"]+)"', src.read_text()):  # the headers beside it (eval.h, exp4.h, ...)
        (tmp_path / name).write_text(sgd.SOURCE.with_name(name).read_text())
    header = tmp_path / "eval.h"
    assert '#include "eval.h"' in src.read_text()
    flags = sgd.macros(SIZES)
    usual = build._library_path("s", src, flags)
    assert build._library_path("s", src, [*flags, *AVX2_ONLY]) != usual
    header.write_text(header.read_text() + "\n/* edited */\n")
    assert build._library_path("s", src, flags) != usual


def test_extra_flags_must_be_compiler_options():
    for bad in ("-mno-avx512f", ["mno-avx512f"], [3]):
        with pytest.raises(ValueError, match="extra_flags: a sequence of options like '-mno-avx512f', not "):
            load(SIZES, bad)
