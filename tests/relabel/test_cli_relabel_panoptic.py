"""``hpe relabel-panoptic`` through click's CliRunner."""

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from conftest import hpe

ROOT = Path(__file__).resolve().parents[2]
SYNTH = ROOT / "sample_data" / "panoptic_synth"
REAL_SAMPLE = ROOT / "sample_data" / "panoptic_160906_pizza1"


def test_help_has_examples():
    r = hpe("relabel-panoptic", "--help")
    assert r.exit_code == 0
    assert "Examples:" in r.output and "hpe relabel-panoptic" in r.output and "--legacy-whenet" in r.output


def test_table_output_and_accounting(tmp_path):
    out, rej = tmp_path / "labels.parquet", tmp_path / "rejects.csv"
    r = hpe("relabel-panoptic", SYNTH, "-o", out, "--rejects", rej)
    assert r.exit_code == 0, r.output
    t = pq.read_table(out)
    cols = t.column_names
    assert cols[:5] == ["sequence", "frame", "camera", "person_id", "image"]
    for c in [
        "bbox_x",
        "bbox_y",
        "bbox_w",
        "bbox_h",
        "pitch",
        "yaw",
        "roll",
        "pitch_2",
        "yaw_2",
        "roll_2",
        "r00",
        "r22",
        "gimbal_lock",
        "roundtrip_err",
        "fit_rmse",
        "n_pairs",
        "scale",
        "lm0_x",
        "lm69_y",
    ]:
        assert c in cols, c
    assert "lm70_x" not in cols and "legacy_yaw" not in cols
    meta = t.schema.metadata
    assert meta[b"hpe:system"] == b"300w_lp" and b"hpe:relabel" in meta
    df = t.to_pandas()
    rj = pd.read_csv(rej)
    assert list(rj.columns) == [
        "sequence",
        "frame",
        "person_id",
        "camera",
        "reason",
        "detail",
        "fit_rmse",
        "n_pairs",
        "scale",
    ]
    gt = pd.read_csv(SYNTH / "ground_truth.csv")
    assert len(df) + len(rj) == len(gt) * 7  # every face in every HD camera, once
    assert set(rj.reason) == {"too few confident points", "behind camera", "outside image"}
    assert df.sequence.unique().tolist() == ["panoptic_synth"]
    assert (df.bbox_w > 0).all() and (df.bbox_x >= 0).all() and (df.bbox_x + df.bbox_w <= 1920 + 1e-9).all()
    # the summary counts what the files hold
    assert f"labelled {len(df)} of {len(gt) * 7} views" in r.output
    assert f"{(rj.reason == 'behind camera').sum()} behind camera" in r.output


def test_refuses_to_overwrite(tmp_path):
    out = tmp_path / "labels.csv"
    out.write_text("keep me")
    r = hpe("relabel-panoptic", SYNTH, "-o", out)
    assert r.exit_code == 1 and "already exists" in r.output and out.read_text() == "keep me"
    r = hpe("relabel-panoptic", SYNTH, "-o", out, "--overwrite", "-q")
    assert r.exit_code == 0 and r.output == ""
    assert pd.read_csv(out).shape[0] > 100


def test_options_cameras_frames_every_workers(tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    r = hpe("relabel-panoptic", SYNTH, "-o", a, "--cameras", "00_00,00_02", "--frames", "100:110", "--every", "2", "-q")
    assert r.exit_code == 0, r.output
    df = pd.read_parquet(a)
    assert set(df.camera) == {"00_00", "00_02"} and sorted(set(df.frame)) == [100, 102, 106, 108]
    r = hpe(
        "relabel-panoptic",
        SYNTH,
        "-o",
        b,
        "--cameras",
        "00_00,00_02",
        "--frames",
        "100:110",
        "--every",
        "2",
        "-q",
        "--workers",
        "2",
    )
    assert r.exit_code == 0, r.output
    pd.testing.assert_frame_equal(df, pd.read_parquet(b))


def test_system_and_preset(tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    assert hpe("relabel-panoptic", SYNTH, "-o", a, "-q").exit_code == 0
    assert hpe("relabel-panoptic", SYNTH, "-o", b, "-q", "--system", "6drepnet", "--preset", "directmhp").exit_code == 0
    x, y = pd.read_parquet(a), pd.read_parquet(b)
    key = ["frame", "person_id", "camera"]
    m = x.merge(y, on=key, suffixes=("", "_6d"))
    A = m[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)
    G = m[[f"r{i}{j}_6d" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)
    np.testing.assert_allclose(G, np.swapaxes(A, 1, 2), atol=1e-12)  # SPEC §3: 6DRepNet's G = A.T
    assert (m.bbox_w_6d < m.bbox_w).all()  # DirectMHP's helmet (radius 18) is smaller than WHENet's (22)
    assert pq.read_schema(b).metadata[b"hpe:system"] == b"6drepnet"


def test_legacy_summary_and_columns(tmp_path):
    out = tmp_path / "legacy.parquet"
    r = hpe("relabel-panoptic", SYNTH, "-o", out, "--legacy-whenet")
    assert r.exit_code == 0, r.output
    df = pd.read_parquet(out)
    assert {"legacy_pitch", "legacy_yaw", "legacy_roll"} <= set(df.columns)
    assert "WHENet's legacy rule dropped" in r.output and "%)" in r.output


@pytest.mark.parametrize("fmt, name", [("whenet", "annotation.txt"), ("coco", "train.json")])
def test_other_formats(tmp_path, fmt, name):
    pytest.importorskip(f"hpe_cli.io.{'coco' if fmt == 'coco' else 'whenet_txt'}")
    out = tmp_path / name
    r = hpe("relabel-panoptic", SYNTH, "-o", out, "--format", fmt, "-q")
    assert r.exit_code == 0, r.output
    table = tmp_path / "t.parquet"
    assert hpe("relabel-panoptic", SYNTH, "-o", table, "-q", "--system", "whenet").exit_code == 0
    df = pd.read_parquet(table)
    if fmt == "whenet":
        lines = out.read_text().splitlines()
        assert len(lines) == len(df)
        image, yaw, pitch, roll = lines[0].split(",")
        assert image == df.image[0] and float(yaw) == df.yaw[0] and float(pitch) == df.pitch[0]
    else:
        doc = json.loads(out.read_text())
        assert len(doc["annotations"]) == len(df)
        ann = doc["annotations"][0]
        assert ann["euler_angles"] == [df.pitch[0], df.yaw[0], df.roll[0]]
        assert doc["images"][0]["width"] == 1920 and len(ann["face2d_pts"]) == 2
    # the format follows the extension by default
    out2 = tmp_path / ("b.txt" if fmt == "whenet" else "b.json")
    assert hpe("relabel-panoptic", SYNTH, "-o", out2, "-q").exit_code == 0
    assert out2.read_text() == out.read_text()


def test_usage_errors(tmp_path):
    out = tmp_path / "x.parquet"
    r = hpe("relabel-panoptic", SYNTH, "-o", tmp_path / "a.txt", "--format", "whenet", "--system", "300w_lp")
    assert r.exit_code == 2 and "whenet system" in r.output
    assert hpe("relabel-panoptic", SYNTH, "-o", out, "--frames", "9:3").exit_code == 2
    assert hpe("relabel-panoptic", SYNTH, "-o", out, "--every", "0").exit_code == 2
    assert hpe("relabel-panoptic", SYNTH, "-o", out, "--max-rmse", "-1").exit_code == 2
    assert hpe("relabel-panoptic", SYNTH, "-o", out, "--system", "nope").exit_code == 2
    assert hpe("relabel-panoptic", tmp_path / "missing", "-o", out).exit_code == 2
    assert not out.exists()


def test_user_errors_are_one_line(tmp_path):
    out = tmp_path / "x.parquet"
    r = hpe("relabel-panoptic", SYNTH, "-o", out, "--cameras", "99_99")
    assert r.exit_code == 1 and r.output.startswith("Error: ") and "99_99" in r.output
    assert r.output.count("\n") == 1 and "Traceback" not in r.output
    r = hpe("relabel-panoptic", SYNTH, "-o", out, "--cameras", "vga")
    assert r.exit_code == 1 and "expected hd cameras" in r.output
    r = hpe("relabel-panoptic", SYNTH, "-o", tmp_path / "x.xlsx")
    assert r.exit_code == 1 and "expected an output ending in .parquet or .csv" in r.output
    # a truncated face file: one line naming it, and no half-written output
    seq = tmp_path / "seq"
    shutil.copytree(SYNTH, seq)
    bad = seq / "hdFace3d" / "faceRecon3D_hd00000110.json"
    bad.write_text(bad.read_text()[:500])
    rej = tmp_path / "rej.csv"
    r = hpe("relabel-panoptic", seq, "-o", out, "--rejects", rej)
    assert r.exit_code == 1 and "faceRecon3D_hd00000110.json: not valid JSON" in r.output
    assert not out.exists() and not rej.exists() and not list(tmp_path.glob(".x.parquet*"))
    # ... which --frames can step around
    r = hpe("relabel-panoptic", seq, "-o", out, "--frames", ":110", "-q")
    assert r.exit_code == 0 and out.exists()


def test_nan_landmarks_become_rejects(tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(SYNTH, seq)
    f = seq / "hdFace3d" / "faceRecon3D_hd00000100.json"
    doc = json.loads(f.read_text())
    doc["people"][0]["face70"]["landmarks"] = [float("nan")] * 210
    f.write_text(json.dumps(doc))
    rej = tmp_path / "rej.parquet"
    r = hpe("relabel-panoptic", seq, "-o", tmp_path / "x.parquet", "--frames", "100:101", "--rejects", rej, "-q")
    assert r.exit_code == 0, r.output
    rj = pd.read_parquet(rej)
    first = rj[(rj.frame == 100) & (rj.person_id == doc["people"][0]["id"])]
    assert len(first) == 7 and set(first.reason) == {"too few confident points"}


def test_real_sample(tmp_path):
    out, rej = tmp_path / "real.parquet", tmp_path / "rej.csv"
    r = hpe("relabel-panoptic", REAL_SAMPLE, "-o", out, "--rejects", rej)
    assert r.exit_code == 0, r.output
    df, rj = pd.read_parquet(out), pd.read_csv(rej)
    assert df.sequence.unique().tolist() == ["160906_pizza1"]
    assert len(df) + len(rj) == 23 * 31
    bad = rj[(rj.frame == 6577) & (rj.person_id == 2)]
    assert len(bad) == 31 and set(bad.reason) == {"bad fit"}
    assert set(rj[(rj.frame == 5777) & (rj.person_id == 2)].reason) == {"too few confident points"}
    assert "fit RMSE (cm) of fitted faces: median" in r.output and "2 bad fits (--max-rmse 2)" in r.output
    r = hpe("relabel-panoptic", REAL_SAMPLE, "-o", tmp_path / "loose.parquet", "--max-rmse", "inf", "-q")
    assert r.exit_code == 0 and len(pd.read_parquet(tmp_path / "loose.parquet")) > len(df)


def test_nothing_labelled_still_writes_typed_files(tmp_path):
    out, rej = tmp_path / "none.parquet", tmp_path / "rej.parquet"
    r = hpe(
        "relabel-panoptic", SYNTH, "-o", out, "--cameras", "00_05", "--rejects", rej, "-q"
    )  # the camera facing the wall
    assert r.exit_code == 0, r.output
    t = pq.read_table(out)
    assert t.num_rows == 0 and "lm69_y" in t.column_names and str(t.schema.field("image").type) == "string"
    assert set(pd.read_parquet(rej).reason) == {"behind camera", "too few confident points"}
    seq = tmp_path / "empty"
    (seq / "hdFace3d").mkdir(parents=True)
    shutil.copy(SYNTH / "calibration_panoptic_synth.json", seq / "calibration_empty.json")
    (seq / "hdFace3d" / "faceRecon3D_hd00000001.json").write_text('{"version": 0.7, "univTime": 3.0, "people": []}')
    r = hpe("relabel-panoptic", seq, "-o", tmp_path / "e.csv")
    assert r.exit_code == 0 and "0 faces x 7 cameras" in r.output
    assert (tmp_path / "e.csv").read_text().startswith('"sequence","frame","camera"')
