"""The audit's duplicate key (one 64-bit hash a row) and its search, against independent oracles.

Equal rows must get equal hashes and distinct rows distinct ones, also for the rows that differ in a pattern a
weak row hash confuses (signs flipped in two columns, swapped columns, -0.0 and 0.0, NaN, integer ids near
2**53); the repeated hashes are the same whatever the thread count; and the JSON report, the ``-o`` table
and the duplicates are the same bytes whatever ``--threads``. A plain audit of a Parquet table never imports
pandas or pyarrow.compute (0.1-0.4 s of start-up each, against a read floor of about 0.4 s at 10M rows).
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hpe_cli
from conftest import hpe
from hpe_cli.pipelines.audit.duplicates import key_hashes, key_words, repeated_values

ROOT = Path(hpe_cli.__file__).resolve().parents[1]  # the hpe_cli this test session imports


def _exact_key(row):
    """A row's key as Python values compared exactly (-0.0 is 0.0, every NaN one NaN), the oracle."""
    return tuple("nan" if isinstance(v, float) and v != v else (v + 0.0 if isinstance(v, float) else v) for v in row)


def _structured_rows():
    vals = [0.0, -0.0, 1.5, -1.5, 90.0, -90.0, 1e-300, -1e-300, np.inf, -np.inf, np.nan, 2.0**-1074]
    ids = [0, 1, -1, 7, 2**53, -(2**53), 2**52 + 1]
    rows = list(itertools.product(vals, vals, vals[:6], ids))
    rng = np.random.default_rng(4)
    again = [rows[i] for i in rng.choice(len(rows), 500)]  # exact repeats
    flipped = [(-p, -y, r, i) for p, y, r, i in rows[:2000]]  # both signs flipped
    swapped = [(y, p, r, i) for p, y, r, i in rows[:2000]]
    return rows + again + flipped + swapped


def test_row_hashes_are_equal_exactly_for_equal_rows():
    rows = _structured_rows()
    pitch, yaw, roll, ids = (list(c) for c in zip(*rows))
    batch = pa.RecordBatch.from_arrays(
        [pa.array(ids, pa.int64()), pa.array(pitch), pa.array(yaw), pa.array(roll)], ["id", "pitch", "yaw", "roll"]
    )
    cols = [np.asarray(c, dtype=np.float64) for c in (pitch, yaw, roll)]
    h = key_hashes(cols, batch, ("id",))
    keys = [_exact_key((p, y, r, float(i))) for p, y, r, i in rows]  # the key compares ids as float64
    groups = {}
    for k, v in zip(keys, h):
        groups.setdefault(k, set()).add(int(v))
    assert all(len(s) == 1 for s in groups.values())  # equal rows, equal hashes
    assert len({next(iter(s)) for s in groups.values()}) == len(groups)  # distinct rows, distinct hashes


def test_integer_key_words_are_arrows_float64_cast():
    v = np.array([0, 1, -1, 2**53, -(2**53), 2**53 - 1, 123456789012345, -7], dtype=np.int64)
    for typ in (pa.int64(), pa.int32()):
        arr = pa.array(v if typ == pa.int64() else v[np.abs(v) < 2**31], typ)
        batch = pa.RecordBatch.from_arrays([arr], ["id"])
        ref = pc.cast(arr, pa.float64()).to_numpy(zero_copy_only=False) + 0.0
        assert np.array_equal(key_words(batch, "id"), ref.view(np.uint64))


def test_duplicates_match_pandas_on_a_large_rounded_table():
    rng = np.random.default_rng(8)
    n = 300_000
    pyr = np.round(rng.normal(0, 4, (n, 3)), 0)  # coarse: many equal angles, many equal rows
    pyr[rng.choice(n, 2000)] *= -1.0
    ids = rng.integers(0, 5, n)
    batch = pa.RecordBatch.from_arrays([pa.array(ids)], ["id"])
    h = key_hashes([np.ascontiguousarray(pyr[:, k]) for k in range(3)], batch, ("id",))
    df = pd.DataFrame({"p": pyr[:, 0] + 0.0, "y": pyr[:, 1] + 0.0, "r": pyr[:, 2] + 0.0, "id": ids})
    assert df.duplicated().sum() > 1000
    assert np.array_equal(pd.Series(h).duplicated().to_numpy(), df.duplicated().to_numpy())


@pytest.mark.parametrize("threads", [1, 2, 3, 4, 7])
def test_repeated_values_do_not_depend_on_threads(threads):
    rng = np.random.default_rng(threads)
    H = rng.integers(0, 2**63, (1 << 20) + 5000, dtype=np.int64).view(np.uint64) * np.uint64(2)
    H[rng.choice(len(H), 3000)] = H[rng.choice(len(H), 3000)]
    H[:3] = [0, 2**64 - 1, 2**63]  # the ends of the ranges
    H[10:13] = H[:3]
    u, c = np.unique(H, return_counts=True)
    assert np.array_equal(repeated_values(H, threads), u[c > 1])


def test_audit_outputs_do_not_depend_on_threads(tmp_path):
    rng = np.random.default_rng(2)
    n = 40_000
    pyr = np.round(rng.uniform(-120, 120, (n, 3)), 0)
    pyr[::53, 1] = 90.0
    pyr[::211] = np.nan
    pyr[30_000:35_000] = pyr[:5000]  # the same name and angles: duplicates (NaN rows too)
    names = np.array([f"im{i % 30_000}.jpg" for i in range(n)], dtype=object)
    pq.write_table(
        pa.table({"image": names, "pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2]}), tmp_path / "a.parquet"
    )
    out = {}
    for t in (1, 2, 3):
        j, o = tmp_path / f"r{t}.json", tmp_path / f"f{t}.parquet"
        hpe("audit", tmp_path / "a.parquet", "--json", j, "-o", o, "--threads", t, "--batch-size", 4096, "-q", ok=True)
        out[t] = (j.read_bytes(), o.read_bytes())
    assert out[1] == out[2] == out[3]
    rep = json.loads(out[1][0])
    key = pd.DataFrame({"p": pyr[:, 0] + 0.0, "y": pyr[:, 1] + 0.0, "r": pyr[:, 2] + 0.0, "image": names})
    dup = key.duplicated().to_numpy()
    assert rep["duplicates"] == int(dup.sum()) > 0
    assert np.array_equal(pq.read_table(tmp_path / "f1.parquet").column("duplicates").to_numpy(), dup)


CHILD = """
import sys
from hpe_cli.cli.main import cli
cli.main(sys.argv[1:], standalone_mode=False)
print("LOADED", sorted(m for m in ("pandas", "pyarrow.compute") if m in sys.modules))
"""


def test_plain_audit_does_not_import_pandas_or_arrow_compute(tmp_path):
    rng = np.random.default_rng(3)
    n = 5000
    g = rng.uniform(-80, 80, (n, 3))
    g[4990:] = g[:10]  # the same id, image and angles as the first 10 rows
    t = pa.table({"id": np.arange(n) % 4990, "image": [f"im{k % 4990}" for k in range(n)], "pitch": g[:, 0]})
    pq.write_table(
        t.append_column("yaw", pa.array(g[:, 1])).append_column("roll", pa.array(g[:, 2])), tmp_path / "a.parquet"
    )
    args = ["audit", tmp_path / "a.parquet", "--json", tmp_path / "r.json", "-q"]
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, "-c", CHILD, *map(str, args)], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert "LOADED []" in r.stdout, r.stdout
    assert json.loads((tmp_path / "r.json").read_text())["duplicates"] == 10


@pytest.mark.parametrize("announced", [None, 0, 5, 12, 20])
def test_duplicates_with_or_without_the_row_count(announced):
    from hpe_cli.pipelines.audit.duplicates import Duplicates

    H = np.array([5, 9, 5, 1, 9, 9, 3, 7, 1, 2, 2, 8], dtype=np.uint64)
    d = Duplicates(announced)
    for lo in range(0, len(H), 5):
        d.add(H[lo : lo + 5], np.arange(lo, min(lo + 5, len(H))) + 2)
    assert d.finish(threads=2) == 5  # rows 2, 4, 5, 8, 10 repeat rows 0, 1, 1, 3, 9
    assert d.dup_idx.tolist() == [2, 4, 5, 8, 10]
    assert d.first_idx.tolist() == [0, 1, 1, 3, 9]


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("announced", [None, 400_000, 300_000])
@pytest.mark.parametrize("store", ["kernels", "numpy", "one_value_often"])
def test_duplicate_rows_from_either_store_match_numpy(threads, announced, store, monkeypatch):
    from hpe_cli.native import kernels
    from hpe_cli.pipelines.audit.duplicates import Duplicates

    if store == "numpy":  # the value halves sorted by numpy (with the kernels: the hash buckets)
        monkeypatch.setenv("HPE_KERNELS", "numpy")
    rng = np.random.default_rng(11)
    H = rng.integers(0, 2**63, 400_000, dtype=np.int64).view(np.uint64) * np.uint64(2)
    H[rng.choice(len(H), 900)] = H[rng.choice(len(H), 900)]  # repeats in both halves
    if store == "one_value_often":  # 20,000 equal rows: their hash bucket overflows, the buckets fall back
        H[rng.choice(len(H), 20_000, replace=False)] = H[7]
    d = Duplicates(announced)  # 300,000 announced: more rows than that come, the store falls back
    full = store == "one_value_often" and d.buckets is not None
    if store != "numpy" and announced and kernels() is not None:
        assert d.buckets is not None  # the buckets are what runs with the kernels
    for lo in range(0, len(H), 65536):
        h = H[lo : lo + 65536]
        slot = d.slot(lo, len(h))  # where a worker writes a batch's hashes when the in-order array has room
        if slot is not None:
            slot[:] = h
            h = slot
            d.file(slot)  # and files them into the value halves (any order: they are sorted)
        d.add(h, np.arange(lo, min(lo + 65536, len(H))) + 1)
    _, first = np.unique(H, return_index=True)
    dup = np.ones(len(H), bool)
    dup[first] = False
    assert full == (d.buckets is not None and d.buckets.full)
    assert d.finish(threads) == int(dup.sum()) > 0
    assert np.array_equal(d.dup_idx, np.flatnonzero(dup))
    firsts = {}
    for i, v in enumerate(H.tolist()):
        firsts.setdefault(v, i)
    assert d.first_idx.tolist() == [firsts[v] for v in H[dup].tolist()]


def test_malloc_thresholds_are_left_alone_outside_a_command(monkeypatch):
    from hpe_cli.pipelines import heap

    calls = []
    monkeypatch.setattr(heap, "raise_malloc_thresholds", lambda *a: calls.append(a) or True)
    assert heap.keep_freed_memory() is False  # library use: no command's transaction is open
    assert calls == []


def test_prefault_maps_the_pages_and_changes_no_value():
    import threading

    from hpe_cli.pipelines.heap import prefault, small_page_array

    a, b = small_page_array(3 << 20, np.uint64), small_page_array(5, np.float64)
    a[:4] = [1, 2, 3, 4]  # values written before, during and after the pages are faulted in stay as written
    prefault(a, b, np.zeros(7))  # an ordinary numpy array is left alone
    a[-1] = 9
    for t in threading.enumerate():
        if t.name == "hpe-prefault":
            t.join()
    b[:] = 0.5
    assert a[:4].tolist() == [1, 2, 3, 4] and a[-1] == 9 and not a[4:-1].any() and b.tolist() == [0.5] * 5


@settings(max_examples=200, deadline=None)
@given(st.lists(st.booleans(), max_size=20_000), st.integers(0, 12))
def test_first_true_is_the_head_of_flatnonzero(bits, k):
    from hpe_cli.pipelines.audit.job import first_true

    m = np.array(bits, dtype=bool)
    assert first_true(m, k).tolist() == np.flatnonzero(m)[:k].tolist()
