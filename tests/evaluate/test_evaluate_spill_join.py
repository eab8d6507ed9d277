"""The external hash join (files in different orders, partitioned on disk) gives the in-memory join's report.

Both golden sets, predictions shuffled, partitions forced small (a few rows each) so every key crosses
partition files; also --by, --yaw-bins, --align mean, opal23-align (a second pass), missing / unmatched /
invalid rows, keys spelled differently (file stems) and duplicates found across the whole file.
"""

import math
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from hpe_cli.errors import HpeError
from hpe_cli.pipelines.evaluate import EvaluateOptions, run_evaluate
from hpe_cli.rotation.systems import get_system

GOLD = Path(__file__).resolve().parents[3] / "shared" / "golden" / "evaluate"
pytestmark = pytest.mark.skipif(not GOLD.is_dir(), reason="shared/golden/evaluate not available")
S = get_system("300w_lp")


def _close(a, b, path=""):
    if isinstance(a, dict):
        assert set(a) == set(b), (path, set(a) ^ set(b))
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-9 * max(1.0, abs(b)), (path, a, b)
    else:
        assert a == b, (path, a, b)


def _both(tmp_path, pred, gt, **kw):
    out = {}
    for engine in ("memory", "spill"):
        o = tmp_path / f"{engine}.parquet"
        rej = tmp_path / f"{engine}_rejects.csv"
        rep = run_evaluate(
            pred,
            gt,
            EvaluateOptions(
                pred_system=S,
                gt_system=S,
                output=o,
                rejects=rej,
                batch_size=97,
                join_engine=engine,
                partition_rows=7,
                overwrite=True,
                **kw,
            ),
        )
        rows = pq.read_table(o).to_pandas().sort_values("image").reset_index(drop=True)
        rj = pd.read_csv(rej) if rej.exists() else None
        out[engine] = (rep, rows, rj)
    (rm, om, jm), (rs, os_, js) = out["memory"], out["spill"]
    assert rm["inputs"].pop("paired") == "joined in memory"
    assert "partition(s) on disk" in rs["inputs"].pop("paired")
    _close(rm, rs)
    pd.testing.assert_frame_equal(om, os_, check_exact=False, rtol=1e-12, atol=1e-12)
    if jm is not None:
        key = [c for c in ("side", "line", "reason") if c in jm.columns]
        pd.testing.assert_frame_equal(
            jm.sort_values(key).reset_index(drop=True), js.sort_values(key).reset_index(drop=True)
        )
    return rs


@pytest.mark.parametrize("name", ["aflw16m", "syn"])
def test_spill_join_equals_memory_join(tmp_path, name):
    pred = tmp_path / "pred.csv"
    pd.read_csv(GOLD / name / "pred.csv").sample(frac=1.0, random_state=3).to_csv(pred, index=False)
    rep = _both(tmp_path, pred, GOLD / name / "gt.csv", by="image", yaw_bins=30)
    assert rep["n"]["pairs"] == len(pd.read_csv(pred))
    rep = _both(tmp_path, pred, GOLD / name / "gt.csv", align="mean", protocols=["opal23-align", "hopenet"])
    assert rep["align"]["method"] == "mean"


def test_spill_join_rejects_and_stems(tmp_path):
    gt = pd.read_csv(GOLD / "syn" / "gt.csv")
    pred = gt.sample(frac=1.0, random_state=5).iloc[:-40].copy()  # 40 GT rows without prediction
    pred["yaw"] += 3.0
    pred.loc[pred.index[:5], "pitch"] = float("nan")  # invalid predictions
    extra = pred.iloc[:6].copy()
    extra["image"] = [f"zz{i}" for i in range(6)]  # predictions with no GT row
    pred = pd.concat([pred, extra])
    pred["image"] = "imgs/" + pred["image"] + ".jpg"  # spelled differently: joined on file stems
    p = tmp_path / "pred.csv"
    pred.to_csv(p, index=False)
    rep = _both(tmp_path, p, GOLD / "syn" / "gt.csv")
    assert rep["n"]["missing"] == 40 and rep["n"]["unmatched_pred"] == 6 and rep["n"]["invalid"] == 5
    assert any("file stems" in n for n in rep["notes"])


def test_duplicate_key_found_across_the_whole_file(tmp_path):
    gt = pd.read_csv(GOLD / "syn" / "gt.csv")
    pred = gt.sample(frac=1.0, random_state=7)
    pred = pd.concat([pred, pred.iloc[[3]]])  # the same key again, 2000 rows later (another chunk)
    p = tmp_path / "pred.csv"
    pred.to_csv(p, index=False)
    with pytest.raises(HpeError, match=r"duplicate key image='s\d+' \(again at line 2002\)"):
        run_evaluate(
            p, GOLD / "syn" / "gt.csv", EvaluateOptions(pred_system=S, gt_system=S, batch_size=97, partition_rows=50)
        )
    assert not list(tmp_path.glob("*.parquet"))


def test_hash_collisions_fall_back_to_the_string_join(tmp_path, monkeypatch):
    """Key hashes only propose matches: equal hashes on one side, or a match whose keys differ, make the
    partition use the string join, so the report is the same."""
    import numpy as np

    from hpe_cli.pipelines.evaluate import spill as es

    pred = tmp_path / "pred.csv"
    pd.read_csv(GOLD / "syn" / "pred.csv").sample(frac=1.0, random_state=3).to_csv(pred, index=False)
    want = _both(tmp_path, pred, GOLD / "syn" / "gt.csv")
    calls = {"hash": 0, "none": 0}
    codes = es.Partitions.codes

    def counted(self, gt, p, stems):
        out = codes(self, gt, p, stems)
        calls["hash" if out is not None else "none"] += 1
        return out

    monkeypatch.setattr(es.Partitions, "codes", counted)
    side = es._SideSpill.side

    def rolled(self, k, empty_keys):  # every prediction's hash moved to the next row: all matches wrong
        out = side(self, k, empty_keys)
        if self.name == "pred" and out.n > 1:
            out.hashes = {j: (np.roll(hx, 1), np.roll(hs, 1)) for j, (hx, hs) in out.hashes.items()}
        return out

    r = run_evaluate(
        pred, GOLD / "syn" / "gt.csv", EvaluateOptions(pred_system=S, gt_system=S, batch_size=97, partition_rows=300)
    )
    assert calls["hash"] > 0 and calls["none"] == 0  # the hash join is the normal path
    monkeypatch.setattr(es._SideSpill, "side", rolled)
    calls.update(hash=0, none=0)
    r2 = run_evaluate(
        pred, GOLD / "syn" / "gt.csv", EvaluateOptions(pred_system=S, gt_system=S, batch_size=97, partition_rows=300)
    )
    assert calls["none"] > 0 and calls["hash"] == 0
    import hpe_cli.io.key_hash as kh

    zeros = lambda arr: (np.zeros(len(arr), dtype=np.uint64),) * 2  # noqa: E731 - every key collides
    monkeypatch.setattr(kh, "string_hashes", zeros)
    r3 = run_evaluate(
        pred, GOLD / "syn" / "gt.csv", EvaluateOptions(pred_system=S, gt_system=S, batch_size=97, partition_rows=300)
    )
    for rep in (r, r2, r3):
        _close({k: want[k] for k in ("metrics", "protocols", "n")}, {k: rep[k] for k in ("metrics", "protocols", "n")})
