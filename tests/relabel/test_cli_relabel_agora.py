"""``hpe relabel-agora`` end to end on the synthetic AGORA fixture."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from conftest import hpe

DATA = Path(__file__).resolve().parents[1] / "data" / "agora"
PKL = DATA / "validation_0_withjv.pkl"
EXPECTED = json.loads((DATA / "expected.json").read_text())["people"]
N_PEOPLE = len(EXPECTED)
N_OK = sum(e["status"].startswith("ok") for e in EXPECTED)


def test_help_has_examples_and_pickle_warning():
    r = hpe("relabel-agora", "--help")
    assert r.exit_code == 0
    assert "Examples:" in r.output and "restricted unpickler" in r.output and "--trust-pickle" in r.output


def test_table_and_rejects(tmp_path):
    out, rej = tmp_path / "labels.parquet", tmp_path / "rejects.csv"
    before = PKL.read_bytes()
    r = hpe("relabel-agora", PKL, "-o", out, "--rejects", rej)
    assert r.exit_code == 0, r.output
    assert PKL.read_bytes() == before  # input untouched
    t = pq.read_table(out)
    cols = t.column_names
    for c in (
        "source",
        "row",
        "person",
        "image",
        "bbox_x",
        "bbox_h",
        "pitch",
        "yaw",
        "roll",
        "pitch_2",
        "r22",
        "gimbal_lock",
        "roundtrip_err",
        "fit_rmse",
        "n_pairs",
        "scale",
        "occlusion",
        "image_width",
        "image_height",
        "lm0_x",
        "lm50_y",
    ):
        assert c in cols
    assert "lm51_x" not in cols
    assert t.num_rows == N_OK
    meta = t.schema.metadata
    assert json.loads(meta[b"hpe:system_definition"])["name"] == "300w_lp"
    assert json.loads(meta[b"hpe:relabel"])["source"] == "agora"
    rj = pd.read_csv(rej)
    assert len(rj) + t.num_rows == N_PEOPLE
    assert set(rj["reason"]) == {
        "occluded",
        "invalid",
        "too few confident points",
        "bad fit",
        "behind camera",
        "outside image",
        "box rejected",
    }
    # the summary names every reason and its count
    assert f"labelled {N_OK} of {N_PEOPLE} people" in r.output
    assert "2 box rejected" in r.output and "1 occluded" in r.output and str(rej) in r.output


def test_coco_output(tmp_path):
    out = tmp_path / "agora.json"
    r = hpe("relabel-agora", PKL, "-o", out, "--image-size", "1280x720")
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["categories"][0]["id"] == 1 and doc["info"]["hpe:system"] == "whenet"
    assert {(i["width"], i["height"]) for i in doc["images"]} == {(1280, 720)}
    names = {i["id"]: i["file_name"] for i in doc["images"]}
    by_target = {(e["image"], tuple(e["target"])) for e in EXPECTED if e["status"].startswith("ok")}
    got = set()
    for a in doc["annotations"]:
        assert a["category_id"] == 1 and a["iscrowd"] == 0
        assert len(a["face2d_pts"]) == 2 and len(a["face2d_pts"][0]) == 51
        x, y, w, h = a["bbox"]
        assert a["area"] == pytest.approx(w * h, abs=1e-3) and 0 <= x and x + w <= 1280 and y + h <= 720
        got.add((names[a["image_id"]], tuple(np.round(a["euler_angles"], 6) + 0.0)))
    assert got == {(i, tuple(float(v) for v in t)) for i, t in by_target}


def test_whenet_output_and_legacy(tmp_path):
    out = tmp_path / "annotation.txt"
    r = hpe("relabel-agora", PKL, "-o", out, "--legacy-whenet")
    assert r.exit_code == 0, r.output
    lines = out.read_text().splitlines()
    assert len(lines) == N_OK - 1  # the (120, 20, 10) head has no WHENet triple
    assert "dropped by legacy rule" in r.output
    img, yaw, pitch, roll = lines[0].split(",")
    first = EXPECTED[0]
    assert img == first["image"]
    np.testing.assert_allclose([float(pitch), float(yaw), float(roll)], first["target"], atol=1e-9)


def test_legacy_columns_in_table(tmp_path):
    out = tmp_path / "l.csv"
    r = hpe("relabel-agora", PKL, "-o", out, "--legacy-whenet", "--system", "whenet")
    assert r.exit_code == 0, r.output
    t = pd.read_csv(out)
    np.testing.assert_allclose(t["legacy_yaw"], t["yaw"], atol=1e-9)
    assert len(t) == N_OK - 1


def test_gates(tmp_path):
    r = hpe("relabel-agora", PKL, "-o", tmp_path / "a.csv", "--max-rmse", "inf")
    assert r.exit_code == 0, r.output
    assert len(pd.read_csv(tmp_path / "a.csv")) == N_OK + 1  # the noisy face is labelled now
    r = hpe("relabel-agora", PKL, "-o", tmp_path / "b.csv", "--max-occlusion", "100", "--rejects", tmp_path / "rb.csv")
    assert r.exit_code == 0, r.output
    rb = pd.read_csv(tmp_path / "rb.csv")
    assert "occluded" not in set(rb["reason"]) and (rb["reason"] == "invalid").sum() == 2


def test_several_dataframes(tmp_path):
    df = pd.read_pickle(PKL)
    df["imgPath"] = df["imgPath"].str.replace("validationset", "trainset")
    second = tmp_path / "train_0_withjv.pkl"
    df.to_pickle(second)
    out = tmp_path / "both.parquet"
    r = hpe("relabel-agora", PKL, second, "-o", out, "-v")
    assert r.exit_code == 0, r.output
    t = pq.read_table(out).to_pandas()
    assert len(t) == 2 * N_OK
    assert set(t["source"]) == {"validation_0_withjv.pkl", "train_0_withjv.pkl"}
    assert "from 2 dataframes" in r.output and "body frame" in r.output


def test_refuses_overwrite(tmp_path):
    out = tmp_path / "x.parquet"
    out.write_text("keep")
    r = hpe("relabel-agora", PKL, "-o", out)
    assert r.exit_code == 1 and "already exists" in r.output
    assert out.read_text() == "keep"
    r = hpe("relabel-agora", PKL, "-o", out, "--overwrite", "-q")
    assert r.exit_code == 0 and r.output == ""
    assert pq.read_table(out).num_rows == N_OK


def test_missing_column_is_one_line(tmp_path):
    bad = tmp_path / "bad_withjv.pkl"
    pd.read_pickle(PKL).drop(columns=["occlusion"]).to_pickle(bad)
    out = tmp_path / "x.parquet"
    r = hpe("relabel-agora", bad, "-o", out)
    assert r.exit_code == 1
    assert (
        r.output.strip() == f"Error: {bad}: missing column 'occlusion' (expected an AGORA *_withjv.pkl "
        "ground-truth dataframe)"
    )
    assert not out.exists() and list(tmp_path.iterdir()) == [bad]


def test_usage_errors(tmp_path):
    assert hpe("relabel-agora", PKL, "-o", tmp_path / "a.json", "--system", "6drepnet").exit_code == 2
    assert hpe("relabel-agora", PKL, "-o", tmp_path / "a.csv", "--image-size", "big").exit_code == 2
    assert hpe("relabel-agora", PKL, "-o", tmp_path / "a.csv", "--max-rmse", "-1").exit_code == 2
    assert hpe("relabel-agora", tmp_path / "nope.pkl", "-o", tmp_path / "a.csv").exit_code == 2
    r = hpe("relabel-agora", PKL, "-o", tmp_path / "a.csv", "--image-size", "1000x1000")
    assert r.exit_code == 1 and "principal point" in r.output
    assert not (tmp_path / "a.csv").exists()


def test_frame_crop_rotates_by_the_ray_angle(tmp_path):
    from scipy.spatial.transform import Rotation

    a, b = tmp_path / "cam.parquet", tmp_path / "crop.parquet"
    assert hpe("relabel-agora", PKL, "-o", a, "--rejects", tmp_path / "r1.csv").exit_code == 0
    r = hpe("relabel-agora", PKL, "-o", b, "--frame", "crop", "--rejects", tmp_path / "r2.csv")
    assert r.exit_code == 0, r.output
    ta, tb = pq.read_table(a).to_pandas(), pq.read_table(b).to_pandas()
    assert list(ta["person"]) == list(tb["person"]) and "ray_angle" in tb and "ray_angle" not in ta
    np.testing.assert_array_equal(
        ta[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]], tb[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]]
    )
    mat = lambda t: t[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)  # noqa: E731
    rv = Rotation.from_matrix(mat(tb) @ np.swapaxes(mat(ta), 1, 2)).as_rotvec()
    # A' A^T = E Q^T E: a rotation by the ray angle about an axis in the image plane (SPEC §10)
    np.testing.assert_allclose(np.degrees(np.linalg.norm(rv, axis=1)), tb["ray_angle"], atol=1e-6)
    np.testing.assert_allclose(rv[:, 2], 0.0, atol=1e-9)
    assert tb["ray_angle"].max() > 5
