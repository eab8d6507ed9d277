"""The default run's C library calls per pair do not grow: protocols that share a decomposition compute it once.

Every protocol reproduces its peer's own arithmetic, so its ``atan2``, ``hypot``, ``acos``, ``asin`` and ``sincos``
calls are most of a default ``hpe evaluate`` run's time (docs/performance.md). ``benchmarks/libm.py`` counts
them with a preloaded shim while one chunk is scored; a change that computes a shared decomposition a second
time, or goes through an extra round trip, shows up here as more calls per pair. The bounds are today's counts
(upper bounds: a numpy whose SIMD loops do not call the C library counts fewer).
"""

from __future__ import annotations

import os
import platform
import shutil
import sys

import numpy as np
import pytest

from conftest import repo_module

#: calls per pair of every protocol but opal23-align on one chunk (the fraction: near-lock rows solved again)
BOUNDS = {"atan2": 33.1, "hypot": 10.0, "acos": 7.0, "asin": 2.0, "acosf": 3.0, "sine and cosine": 12.05}

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or shutil.which(os.environ.get("CC", "cc")) is None,
    reason="needs Linux and a C compiler (the counting shim is preloaded with LD_PRELOAD)",
)


def _bench():
    return repo_module("benchmarks/libm.py")


def test_calls_per_pair_within_bounds(tmp_path):
    got = _bench().count_calls(shutil.which(os.environ.get("CC", "cc")), tmp_path, rows=4096)
    if isinstance(got, str):
        pytest.skip(got)
    counts = got["scoring"]
    # one sincos where the kernels are built, a sin and a cos where numpy computes them
    counts["sine and cosine"] = counts["sincos"] + max(counts["sin"], counts["cos"])
    if counts["atan2"] < 10:  # a numpy whose own SIMD loops bypass the C library (the kernels then follow it)
        pytest.skip(f"the C library is not called for most values here: {counts}")
    over = {f: (counts[f], b) for f, b in BOUNDS.items() if counts[f] > b + 1e-9}
    assert not over, f"more C library calls per pair than before (got, bound): {over}"


def test_label_sines_and_cosines_are_one_call(tmp_path):
    """Where the kernels give numpy's bits, each label angle's sine and cosine come from one ``sincos`` call (a
    compiler once split the kernel's call into ``sin`` and ``cos``: 7.5 ns more a value, 0.2 s of CPU at 5M pairs)."""
    from hpe_cli import native

    if native.kernels() is None or native.sin_cos(np.zeros(native._MIN_ROWS))[0] is None:
        pytest.skip("no compiled kernels")
    got = _bench().count_calls(shutil.which(os.environ.get("CC", "cc")), tmp_path, rows=4096)
    if isinstance(got, str):
        pytest.skip(got)
    labels = got["labels"]
    if native._sin_cos_kernel() is None or platform.libc_ver()[0] != "glibc":
        pytest.skip("the kernel's sincos is glibc's, used where it gives numpy's bits")
    assert labels["sincos"] == 6 and labels["sin"] == 0 and labels["cos"] == 0, labels


def test_a_whole_run_is_counted_and_one_protocol_calls_fewer(tmp_path):
    """``count_run`` (what ``benchmarks/evaluate.py --exact-floor`` and ``libm.py --run`` use) counts a whole
    ``hpe evaluate``: every protocol calls the C library more often than hopenet alone, which computes its angle
    errors without it."""
    make_tables = repo_module("benchmarks/evaluate.py").make_tables
    make_tables(2000, tmp_path, False)
    bench, cc = _bench(), shutil.which(os.environ.get("CC", "cc"))
    pred, gt = str(tmp_path / "pred.parquet"), str(tmp_path / "gt.parquet")
    every, one = (bench.count_run(cc, tmp_path, pred, gt, p) for p in ((), ("hopenet",)))
    if isinstance(every, str) or isinstance(one, str):
        pytest.skip(every if isinstance(every, str) else one)
    assert every["pairs"] == one["pairs"] == 2000
    if every["calls"]["atan2"] < 10 * 2000:
        pytest.skip(f"the C library is not called for most values here: {every['calls']}")
    assert one["calls"]["atan2"] < every["calls"]["atan2"] and one["calls"]["acos"] < every["calls"]["acos"]
    costs = {f: 1.0 for f in bench.FUNCS}
    assert bench.libm_seconds(every["calls"], costs) == pytest.approx(sum(every["calls"].values()) * 1e-9)


def test_sites_name_the_kernels_that_call(tmp_path, capsys):
    """``libm.py --sites`` counts a whole run's calls by the function that made them: the kernels by name."""
    from hpe_cli import native

    if native.kernels() is None or shutil.which("addr2line") is None:
        pytest.skip("no compiled kernels or no addr2line")
    repo_module("benchmarks/evaluate.py").make_tables(2000, tmp_path, False)
    _bench().sites(
        shutil.which(os.environ.get("CC", "cc")), tmp_path, str(tmp_path / "pred.parquet"), str(tmp_path / "gt.parquet")
    )
    out = capsys.readouterr().out
    if "skipped" in out:
        pytest.skip(out.strip())
    rows = {line.split()[1]: line.split()[2:] for line in out.splitlines() if line.strip().startswith("kernel ")}
    assert any("core_errors" in name for name in rows), out  # 4 atan2 a pair: hpe's own geodesic and column angles
    assert all(len(counts) == 5 for counts in rows.values())
