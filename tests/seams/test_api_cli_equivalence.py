"""The Python API and the CLI give the same answers on the same input (one implementation per job).

For read_labels, convert, audit, evaluate, augment and draw: call the API
function and the ``hpe`` command on the same labels and compare the outputs
(rotations as matrices, geodesic < 1e-6 degrees; pixels exactly).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import hpe_cli as hpe
from conftest import hpe as hpe_cmd

ROOT = Path(__file__).resolve().parents[2]
MAT_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]


def geo(A, B):
    return hpe.geodesic(np.asarray(A).reshape(-1, 3, 3), np.asarray(B).reshape(-1, 3, 3))


@pytest.fixture
def labels(tmp_path):
    rng = np.random.default_rng(7)
    n = 40
    pyr = np.c_[rng.uniform(-85, 85, n), rng.uniform(-175, 175, n), rng.uniform(-85, 85, n)]
    pyr[3] = [10.0, 90.0, -20.0]  # gimbal lock of 300w_lp
    pyr[4] = [0.0, 120.0, 0.0]  # not the primary solution
    df = pd.DataFrame(pyr, columns=["pitch", "yaw", "roll"])
    df["image"] = [f"im{i:02d}.png" for i in range(n)]
    df["tdx"], df["tdy"] = 40.0 + (np.arange(n) % 5), 30.0
    df["bbox_x"], df["bbox_y"], df["bbox_w"], df["bbox_h"] = 20.0, 10.0, 30.0, 36.0
    path = tmp_path / "labels.csv"
    df.to_csv(path, index=False)
    return path, df, pyr


def test_read_labels_matches_what_the_commands_read(tmp_path):
    out = tmp_path / "l.parquet"
    hpe_cmd(
        "relabel-panoptic", ROOT / "sample_data" / "panoptic_synth", "-o", out, "--system", "scipy_zyx", "-q", ok=True
    )
    table, system = hpe.read_labels(out)
    rep = json.loads(hpe_cmd("audit", out, "--json", "-", "-q", ok=True).stdout)
    assert system.name == rep["system"] == "scipy_zyx" and rep["system_origin"] == "file metadata"
    assert rep["rows"] == len(table)
    same = tmp_path / "same.parquet"
    hpe_cmd("convert", out, "-o", same, "--to", "scipy_zyx", "-q", ok=True)
    back = pd.read_parquet(same)
    R_api = system.from_angles(table[["pitch", "yaw", "roll"]].to_numpy())
    assert geo(R_api, back[MAT_COLS].to_numpy()).max() < 1e-6
    # an explicit system that disagrees is refused by both
    from hpe_cli.errors import UsageError

    with pytest.raises(UsageError):
        hpe.read_labels(out, system="300w_lp")
    assert hpe_cmd("audit", out, "--system", "300w_lp").exit_code == 2


def test_convert(labels, tmp_path):
    path, df, pyr = labels
    out = tmp_path / "c.parquet"
    hpe_cmd("convert", path, "-o", out, "--from", "300w_lp", "--to", "6drepnet", "-q", ok=True)
    cli_out = pd.read_parquet(out)
    api = hpe.convert(pyr, "300w_lp", "6drepnet")
    assert geo(api.matrix, cli_out[MAT_COLS].to_numpy()).max() < 1e-6
    np.testing.assert_allclose(api.primary, cli_out[["pitch", "yaw", "roll"]].to_numpy(), atol=1e-9)
    np.testing.assert_array_equal(api.gimbal_lock, cli_out["gimbal_lock"].to_numpy())
    out2 = tmp_path / "c2.parquet"
    s = hpe.convert_file(path, out2, "6drepnet", "300w_lp")
    assert s.written == len(df) and s.source_origin == "option"
    pd.testing.assert_frame_equal(pd.read_parquet(out2), cli_out)


def test_audit(labels, tmp_path):
    path, _, pyr = labels
    flagged = tmp_path / "f.parquet"
    rep = json.loads(hpe_cmd("audit", path, "--system", "300w_lp", "-o", flagged, "--json", "-", "-q", ok=True).stdout)
    got = pd.read_parquet(flagged)
    api = hpe.audit(pyr, "300w_lp")
    for check in ("gimbal_lock", "near_gimbal", "non_canonical", "out_of_range", "non_finite"):
        np.testing.assert_array_equal(api[check], got[check].to_numpy(), err_msg=check)
        assert rep[check] == int(api[check].sum()), check
    assert api["gimbal_lock"][3] and api["non_canonical"][4]
    rep2 = hpe.audit_file(path, "300w_lp")
    assert {k: rep2[k] for k in ("rows", "non_canonical", "near_gimbal")} == {
        k: rep[k] for k in ("rows", "non_canonical", "near_gimbal")
    }


def test_evaluate(labels, tmp_path):
    path, df, pyr = labels
    rng = np.random.default_rng(3)
    pred = df.copy()
    noisy = pyr + rng.normal(0, 3, pyr.shape)
    pred[["pitch", "yaw", "roll"]] = noisy
    pred = pred.sample(frac=1.0, random_state=1)  # the CLI joins on image, not row order
    pp = tmp_path / "pred.csv"
    pred.to_csv(pp, index=False)
    rep = json.loads(
        hpe_cmd(
            "evaluate", pp, path, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--json", "-", "-q", ok=True
        ).stdout
    )
    api = hpe.evaluate(noisy, pyr, pred_system="300w_lp", gt_system="300w_lp")
    assert rep["n"]["pairs"] == api["n"]["pairs"] == len(df)
    for k in ("pitch", "yaw", "roll"):
        assert rep["metrics"]["mae_wrapped"][k] == pytest.approx(api["metrics"]["mae_wrapped"][k], abs=1e-9)
    assert rep["metrics"]["geodesic"]["mean"] == pytest.approx(api["metrics"]["geodesic"]["mean"], abs=1e-9)


def test_augment(labels, tmp_path):
    path, df, pyr = labels
    out = tmp_path / "a.parquet"
    hpe_cmd("augment", path, "-o", out, "--system", "300w_lp", "--image-size", "64", "64", "--hflip", "-q", ok=True)
    got = pd.read_parquet(out)
    box = df[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy()
    api = hpe.augment_batch(pyr, bbox=box, op="hflip", image_size=(64, 64))
    assert geo(api.matrix, got[MAT_COLS].to_numpy()).max() < 1e-6
    np.testing.assert_allclose(api.bbox, got[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy(), atol=1e-9)


def test_draw(labels, tmp_path):
    path, df, pyr = labels
    outdir = tmp_path / "drawn"
    hpe_cmd("draw", path, "-o", outdir, "--canvas", "96x80", "--length", "20", "--thickness", "1", "-q", ok=True)
    import cv2

    from hpe_cli.geometry.draw import blank_canvas

    for k in (0, 3, 4, 17):
        cli_img = cv2.imread(str(outdir / df["image"][k]))
        centre = (df["bbox_x"][k] + df["bbox_w"][k] / 2, df["bbox_y"][k] + df["bbox_h"][k] / 2)  # draw: box first
        api_img = hpe.draw_axes(blank_canvas(96, 80), pyr[k], centre, 20, thickness=1)
        assert cli_img.shape == api_img.shape
        assert np.array_equal(cli_img, api_img), k
