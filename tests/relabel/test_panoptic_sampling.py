"""Sampling rules on the real pizza1 sample: camera presets, --all-views, --min-change.

Oracles: WHENet's camera list written out here, hand counts, and --min-change re-done independently
(a plain loop with SciPy's rotation magnitudes over the unsampled labels)."""

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe

#: Ascend-Research/HeadPoseEstimation-WHENet prepare_images.py: without_top (panel 0 nodes)
WITHOUT_TOP = [0, 3, 5, 8, 9, 11, 12, 14, 15, 16, 18, 20, 21, 22, 23, 24, 25, 26, 27, 29]


@pytest.fixture
def seq(realdata):
    return realdata / "panoptic_160906_pizza1"


def _mats(t):
    return t[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)


def test_whenet_haggling_cameras_and_all_views(seq, tmp_path):
    o, rj = tmp_path / "o.parquet", tmp_path / "r.csv"
    out = hpe(
        "relabel-panoptic",
        seq,
        "-o",
        o,
        "--rejects",
        rj,
        "--cameras",
        "whenet-haggling",
        "--all-views",
        "--no-landmarks",
        ok=True,
    ).output
    t = pq.read_table(o).to_pandas()
    r = pd.read_csv(rj, dtype={"camera": str})
    assert set(t["camera"]) <= {f"00_{i:02d}" for i in WITHOUT_TOP}
    assert "x 20 cameras" in out
    # every face kept is labelled by all 20 cameras; the others' views are in the rejects
    sizes = t.groupby(["frame", "person_id"]).size()
    assert (sizes == 20).all() and len(sizes) >= 1
    dropped = r[r["reason"] == "not seen by every camera"]
    assert len(dropped) > 0 and dropped["detail"].str.contains(r"of 20 cameras").all()
    faces = set(map(tuple, t[["frame", "person_id"]].to_numpy())) | set(
        map(tuple, r[["frame", "person_id"]].to_numpy())
    )
    assert len(t) + len(r) == len(faces) * 20  # every view accounted for


def test_min_change_matches_an_independent_loop(seq, tmp_path):
    full, samp, rj = tmp_path / "full.parquet", tmp_path / "s.parquet", tmp_path / "r.csv"
    hpe("relabel-panoptic", seq, "-o", full, "--no-landmarks", ok=True).output
    out = hpe(
        "relabel-panoptic",
        seq,
        "-o",
        samp,
        "--no-landmarks",
        "--min-change",
        "20",
        "--rejects",
        rj,
        "--workers",
        "2",
        ok=True,
    ).output
    f = pq.read_table(full).to_pandas()
    s = pq.read_table(samp).to_pandas()
    R = _mats(f)
    keep = np.zeros(len(f), dtype=bool)
    last = {}
    for k in range(len(f)):  # rows are in frame order
        key = (f["sequence"][k], f["person_id"][k], f["camera"][k])
        if key in last and Rotation.from_matrix(R[last[key]].T @ R[k]).magnitude() < np.radians(20):
            continue
        keep[k] = True
        last[key] = k
    want = f[keep].reset_index(drop=True)
    pd.testing.assert_frame_equal(s.reset_index(drop=True), want)
    r = pd.read_csv(rj)
    moved = r[r["reason"] == "below --min-change"]
    assert len(moved) == int((~keep).sum()) > 0
    assert f"{len(moved)} below --min-change" in out


def test_every_and_frames_with_rejects_accounting(seq, tmp_path):
    o, rj = tmp_path / "o.parquet", tmp_path / "r.csv"
    hpe(
        "relabel-panoptic",
        seq,
        "-o",
        o,
        "--rejects",
        rj,
        "--every",
        "2",
        "--frames",
        "1147:6000",
        "--no-landmarks",
        ok=True,
    ).output
    t = pq.read_table(o).to_pandas()
    r = pd.read_csv(rj)
    skipped = r[r["reason"] == "skipped by --every"]  # the frames --every skips are listed, not labelled
    r = r[r["reason"] != "skipped by --every"]
    frames = set(t["frame"]) | set(r["frame"])
    assert frames <= {1147, 1613, 2319, 3476, 3961, 4905, 5777}
    assert all((f - 1147) % 2 == 0 for f in frames)
    assert all((f - 1147) % 2 == 1 and 1147 <= f < 6000 for f in set(skipped["frame"]))
