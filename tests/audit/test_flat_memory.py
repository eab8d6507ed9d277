"""Flat memory of ``hpe audit --consistency``: streamed quantiles, the row spill, a run past the exact limit.

Oracles: numpy's percentile and median on all values at once; the exact run
(every value kept) of the same table.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli.metrics import consistency as mc
from hpe_cli.metrics.sketch import StreamQuantiles
from hpe_cli.pipelines.audit.spill import RECORD, RowSpill


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.lists(st.floats(0.0, 100.0, allow_nan=False), min_size=1, max_size=300),
    st.integers(1, 50),
    st.sampled_from([0.01, 0.1, 1.0]),
)
def test_stream_quantiles_match_numpy(values, cap, res):
    x = np.asarray(values)
    q = StreamQuantiles(100.0, res, exact_cap=cap)
    for chunk in np.array_split(x, 3):
        q.add(chunk)
    want = np.percentile(x, [0, 50, 90, 99, 100])
    got = q.percentile([0, 50, 90, 99, 100])
    assert q.n == len(x) and q.max == x.max() and q.min == x.min()
    if len(x) <= cap:
        assert q.exact
        np.testing.assert_array_equal(got, want)
    else:
        assert not q.exact
        # the bin centre of the value at the rank below numpy's interpolation point
        s = np.sort(x)
        ranks = np.floor(np.array([0, 50, 90, 99, 100]) / 100 * (len(x) - 1)).astype(int)
        assert np.all(np.abs(got - s[ranks]) <= res / 2 + 1e-12)
        assert np.all(np.abs(got - want) <= res / 2 + np.diff(np.append(s, s[-1]))[ranks] + 1e-12)


def test_stream_quantiles_ignore_non_finite_and_say_their_resolution():
    q = StreamQuantiles(10.0, 0.5, exact_cap=2)
    q.add([np.nan, 1.0, np.inf, 2.0, 3.0])
    assert q.n == 3 and not q.exact
    assert q.stats()["resolution"] == 0.5 and q.stats()["max"] == 3.0
    assert StreamQuantiles(1, 1).stats() == {"n": 0}


def test_expected_fit_streamed_is_exact_then_close():
    rng = np.random.default_rng(1)
    yaw = rng.uniform(0, 90, 5000).astype(np.float32)
    ang = 4.0 + 9.0 * (yaw / 90.0) ** 2 * rng.uniform(0.5, 1.5, 5000)
    ang[::50] += 40  # wrong labels: the medians do not move much
    want = mc.fit_expected_landmark_angle(yaw, ang)
    exact = mc.expected_angle_sketch()
    binned = mc.expected_angle_sketch(exact_cap=100)
    for s in range(0, 5000, 700):
        exact.add(yaw[s : s + 700], ang[s : s + 700])
        binned.add(yaw[s : s + 700], ang[s : s + 700])
    assert mc.fit_expected_streamed(exact) == want
    got = mc.fit_expected_streamed(binned)
    assert not binned.exact and got["source"] == want["source"] == "fitted on 5000 rows"
    assert abs(got["a"] - want["a"]) < 0.05 and abs(got["b"] - want["b"]) < 0.1, (got, want)


def test_row_spill_reads_back_what_was_written():
    sp = RowSpill()
    recs = []
    for k in range(3):
        r = RowSpill.empty(1000 + k)
        r["line"] = np.arange(len(r)) + 10_000 * k
        r["lm_angle"] = np.random.default_rng(k).normal(size=len(r))
        r["A"] = np.eye(3).reshape(9)
        sp.append(r)
        recs.append(r)
    allr = np.concatenate(recs)
    assert sp.n == len(allr) and RECORD.itemsize == 61
    np.testing.assert_array_equal(sp.read(500, 1200), allr[500:1700])
    np.testing.assert_array_equal(sp.read(2900, 500), allr[2900:])
    np.testing.assert_array_equal(sp.take([5, 2999, 1001]), allr[[5, 2999, 1001]])
    np.testing.assert_array_equal(np.concatenate([c for _, c in sp.chunks(777)]), allr)
    sp.close()


@pytest.fixture(scope="module")
def lm68_table(tmp_path_factory):
    """3,000 rows of 68 projected landmarks (1 px noise), 5% of the labels turned 30 deg (the benchmark's table)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from consistency import make_table

    path = tmp_path_factory.mktemp("flat") / "lm68.parquet"
    make_table(3000, path, seed=3)
    return path


def _run(path, tmp, **kw):
    from hpe_cli.pipelines.audit import AuditOptions, run_audit
    from hpe_cli.pipelines.audit.consistency import Settings

    out = tmp / f"o{len(kw)}.parquet"
    rep = run_audit(path, None, AuditOptions(output=out, overwrite=True, consistency=Settings(**kw)))
    return json.loads(json.dumps(rep["consistency"])), pq.read_table(out).to_pandas()


def test_past_the_exact_limit_the_ranking_is_the_same(lm68_table, tmp_path):
    exact, ex_rows = _run(lm68_table, tmp_path)
    binned, bi_rows = _run(lm68_table, tmp_path, exact_rows=200)
    assert "resolution" not in exact["landmarks"]["angle_deg"]
    assert binned["landmarks"]["angle_deg"]["resolution"] == 0.001
    for k in ("rows", "checked", "not_checked", "suspects"):
        assert exact[k] == binned[k]
    assert exact["suspects"] > 100
    assert [w["image"] for w in exact["worst"]] == [w["image"] for w in binned["worst"]]
    np.testing.assert_array_equal(ex_rows["suspect"], bi_rows["suspect"])
    np.testing.assert_array_equal(ex_rows["landmark_angle"], bi_rows["landmark_angle"])  # not rescaled
    np.testing.assert_allclose(ex_rows["consistency_score"], bi_rows["consistency_score"], rtol=0.02)
    for k in ("median", "p90", "p99", "max"):
        assert abs(exact["landmarks"]["angle_deg"][k] - binned["landmarks"]["angle_deg"][k]) <= 0.02
    # the -o columns of the exact run agree with the JSON statistics (numpy on all rows)
    v = ex_rows["landmark_angle"].to_numpy(np.float64)
    assert exact["landmarks"]["angle_deg"]["median"] == round(float(np.median(v[np.isfinite(v)])), 3)


# --------------------------------------------------------------------------------------- streamed groups
@pytest.fixture(scope="module")
def panoptic_tables(tmp_path_factory):
    """The synthetic Panoptic labels with one camera turned 4 deg and a glitch frame, sorted and shuffled."""
    import pyarrow as pa

    from tests.audit.test_consistency_audit import _angles_of, _turn
    from tests.conftest import canonical_A, hpe, sample_data_script

    root = tmp_path_factory.mktemp("stream") / "synthseq"
    gen = sample_data_script()
    gen.make_synthetic(root, n_frames=40, n_people=2, n_cameras=6, first_frame=100, special=False)
    lab = root.parent / "labels.parquet"
    assert hpe("relabel-panoptic", root, "-o", lab, "-q", "--rejects", root.parent / "rej.csv").exit_code == 0
    t = pq.read_table(lab)
    A = canonical_A(np.stack([t.column(c).to_numpy() for c in ("pitch", "yaw", "roll")], 1))
    cams = np.array(t.column("camera").to_pylist())
    A[cams == sorted(set(cams))[2]] = _turn([0.2, 1.0, -0.3], 4.0) @ A[cams == sorted(set(cams))[2]]
    frames = t.column("frame").to_numpy()
    pids = t.column("person_id").to_numpy()
    g = (frames == 117) & (pids == pids[0])
    A[g] = _turn([1.0, 0.2, 0.0], 20.0) @ A[g]  # a one-frame glitch of one person in every view
    new = _angles_of(A)
    t2 = t.select([c for c in t.column_names if c not in ("pitch", "yaw", "roll")])
    for k, c in enumerate(("pitch", "yaw", "roll")):
        t2 = t2.append_column(c, pa.array(new[:, k]))
    t2 = t2.replace_schema_metadata(t.schema.metadata)
    order = np.lexsort([t2.column("camera").to_numpy(), t2.column("person_id").to_numpy(), frames])
    srt = root.parent / "sorted.parquet"
    pq.write_table(t2.take(order), srt, row_group_size=100)  # several batches
    shuf = root.parent / "shuffled.parquet"
    pq.write_table(t2.take(np.random.default_rng(0).permutation(len(order))), shuf)
    return srt, shuf


def _audit(path, tmp, **kw):
    from hpe_cli.pipelines.audit import AuditOptions, run_audit
    from hpe_cli.pipelines.audit.consistency import Settings

    out = tmp / f"o_{path.stem}_{len(kw)}.parquet"
    rep = run_audit(path, None, AuditOptions(output=out, overwrite=True, batch_size=97, consistency=Settings(**kw)))
    return json.loads(json.dumps(rep["consistency"])), pq.read_table(out).to_pandas()


def test_streamed_groups_give_the_held_results(panoptic_tables, tmp_path):
    from hpe_cli.io import open_table
    from hpe_cli.pipelines.audit.stream import sorted_by_sequence_frame

    srt, shuf = panoptic_tables
    assert sorted_by_sequence_frame(open_table(srt)) and not sorted_by_sequence_frame(open_table(shuf))
    streamed, s_rows = _audit(srt, tmp_path)
    held, h_rows = _audit(srt, tmp_path, stream_groups=False)
    assert streamed["views"]["cameras_with_offset"] and streamed["time"]["jumps"] > 0
    assert streamed["views"]["groups"] >= 70 and streamed["time"]["checked"] > 300
    for k in ("views", "time", "checked", "not_checked", "not_checked_reasons", "suspects"):
        assert streamed[k] == held[k], k
    cols = ["view_angle", "jump_rate", "consistency_score", "suspect", "consistency_note"]
    pd.testing.assert_frame_equal(s_rows[cols], h_rows[cols])
    # the shuffled table (held rows) has the same rows' results
    sh, sh_rows = _audit(shuf, tmp_path)
    assert sh["views"]["cameras_with_offset"] == held["views"]["cameras_with_offset"]
    assert sh["time"]["jumps"] == held["time"]["jumps"] and sh["suspects"] == held["suspects"]
    key = ["frame", "person_id", "camera"]
    a = h_rows.sort_values(key).reset_index(drop=True)
    b = sh_rows.sort_values(key).reset_index(drop=True)
    np.testing.assert_allclose(a["view_angle"], b["view_angle"], atol=1e-4)
    np.testing.assert_allclose(a["jump_rate"], b["jump_rate"], atol=1e-4)


def test_streamed_groups_past_the_exact_limit(panoptic_tables, tmp_path):
    srt, _ = panoptic_tables
    exact, rows = _audit(srt, tmp_path)
    binned, b_rows = _audit(srt, tmp_path, exact_rows=50)
    assert binned["views"]["cameras_with_offset"] == exact["views"]["cameras_with_offset"]
    got = {b["camera"]: b["offset_deg"] for b in binned["views"]["cameras"]}
    assert len(got) == len(exact["views"]["cameras"])
    for e in exact["views"]["cameras"]:  # the order of the cameras without an offset may change
        assert abs(e["offset_deg"] - got[e["camera"]]) < 0.01, (e, got)
    assert binned["time"]["jumps"] == exact["time"]["jumps"]
    np.testing.assert_array_equal(rows["suspect"], b_rows["suspect"])
