"""300W-LP / AFLW2000-3D ``.mat`` reader against the real files of ``realdata/`` (PROVENANCE.md §1-2).

The oracle is PROVENANCE.md's table (values read independently with scipy and
printed to 2 decimals) and the visibility counts given there per file.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from hpe_cli.datasets.mat import read_mat, read_mat_dir
from hpe_cli.errors import HpeError

REALDATA = Path(__file__).resolve().parents[3] / "shared" / "realdata"
AFLW = REALDATA / "aflw2000_prnet"
W300 = REALDATA / "300wlp_face3d"

pytestmark = pytest.mark.skipif(not AFLW.is_dir() or not W300.is_dir(), reason="shared/realdata not available")

# file: pitch, yaw, roll (deg), tdx, tdy, tdz, visible pt2d points of 21 (PROVENANCE.md §1)
AFLW_TABLE = {
    "image00050": (-4.66, 0.94, 5.64, 229.71, 209.54, -110.88, 21),
    "image00081": (4.46, 17.91, -0.69, 260.30, 186.70, -93.32, 20),
    "image00251": (6.99, -54.69, -14.58, 135.73, 179.68, -50.24, 12),
    "image00430": (34.45, 4.69, 7.25, 237.64, 119.96, -112.21, 21),
    "image00475": (39.96, 65.62, 19.99, 326.60, 161.03, -36.64, 13),
    "image00514": (30.66, -5.27, 6.33, 215.86, 133.20, -113.48, 21),
    "image00516": (-0.99, -35.71, 5.62, 159.46, 196.20, -80.49, 17),
    "image01038": (35.90, 11.06, -6.22, 247.10, 123.98, -105.98, 21),
    "image01322": (-13.59, -5.38, -1.68, 209.67, 230.35, -100.63, 14),
    "image02283": (2.53, -14.14, 2.07, 200.18, 193.81, -101.64, 19),
    "image02420": (-10.32, 70.90, -8.71, 334.23, 197.71, -30.08, 12),
    "image02545": (-30.97, 10.97, -8.81, 250.95, 265.39, -80.45, 20),
    "image02616": (-13.47, 37.97, -13.11, 290.72, 213.58, -70.67, 14),
    "image03324": (17.31, -10.94, -0.87, 205.44, 161.36, -97.18, 20),
    "image03614": (0.35, 17.55, -3.43, 260.01, 192.92, -93.47, 19),
    "image04331": (12.33, 45.45, -1.59, 300.31, 178.07, -61.53, 15),
}


@pytest.mark.parametrize("name", sorted(AFLW_TABLE))
def test_aflw2000_pose_and_visibility(name):
    p, y, r, tdx, tdy, tdz, visible = AFLW_TABLE[name]
    rec = read_mat(AFLW / f"{name}.mat")
    np.testing.assert_allclose(rec["pose"][:6], [p, y, r, tdx, tdy, tdz], atol=0.006)
    pt2d = rec["pt2d"]
    assert pt2d.shape == (2, 21)
    vis = np.isfinite(pt2d).all(0)
    assert vis.sum() == visible
    # an invisible point is NaN in both coordinates, a visible one lies in the 450 x 450 image
    assert np.isnan(pt2d[:, ~vis]).all()
    assert ((pt2d[:, vis] >= 0) & (pt2d[:, vis] < 450)).all()
    assert rec["pt3d_68"].shape == (3, 68)


def test_aflw2000_sample_values():
    rec = read_mat(AFLW / "image00050.mat")
    np.testing.assert_allclose(rec["pt2d"][:, :3], [[151.7, 184.8, 205.9], [188.8, 182.6, 194.0]], atol=0.051)
    assert 0.001454 == pytest.approx(rec["pose"][6], abs=5e-7)
    # rows 0-1 of pt3d_68 are image pixels: the 68 points sit on the face, inside the image
    xy = rec["pt3d_68"][:2]
    assert ((xy > 0) & (xy < 450)).all()


def test_300wlp_file_without_pt3d():
    rec = read_mat(W300 / "IBUG_image_008_1_0.mat")
    assert rec["pt2d"].shape == (2, 68)
    assert np.isfinite(rec["pt2d"]).all()
    assert rec["pt3d_68"] is None
    np.testing.assert_allclose(np.deg2rad(rec["pose"][:3]), [-0.13236, -0.76810, 0.05598], atol=1e-5)
    np.testing.assert_allclose(rec["pose"][3:], [183.575, 189.523, -81.748, 0.0013001], rtol=1e-4)
    np.testing.assert_allclose(rec["pose"][:3], [-7.58, -44.01, 3.21], atol=0.006)


def test_read_mat_dir_table():
    frame = read_mat_dir(AFLW, landmarks=True)
    assert len(frame) == 16
    assert list(frame["file"]) == [f"{n}.mat" for n in sorted(AFLW_TABLE)]
    np.testing.assert_allclose(
        frame[["pitch", "yaw", "roll"]].to_numpy(), [AFLW_TABLE[n][:3] for n in sorted(AFLW_TABLE)], atol=0.006
    )
    lm = frame[[f"lm{i}_x" for i in range(21)]].to_numpy()
    assert (np.isfinite(lm).sum(1) == [AFLW_TABLE[n][6] for n in sorted(AFLW_TABLE)]).all()
    assert "lm67_x" not in frame and "lm3d67_z" in frame


def test_single_300wlp_file_table():
    frame = read_mat_dir(W300 / "IBUG_image_008_1_0.mat", landmarks=True)
    assert len(frame) == 1 and "lm67_y" in frame and not any(c.startswith("lm3d") for c in frame)


@pytest.mark.parametrize("keep", [0.0, 0.03, 0.5, 0.99])
def test_truncated_mat_names_the_file(tmp_path, keep):
    src = AFLW / "image00050.mat"
    data = src.read_bytes()
    bad = tmp_path / "cut.mat"
    bad.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(HpeError) as err:
        read_mat(bad)
    msg = str(err.value)
    assert str(bad) in msg and "\n" not in msg


def test_not_a_mat_file(tmp_path):
    bad = tmp_path / "x.mat"
    bad.write_text("hello, this is not MATLAB\n")
    with pytest.raises(HpeError, match="x.mat"):
        read_mat(bad)


def test_mat_without_pose_para(tmp_path):
    import scipy.io

    f = tmp_path / "nopose.mat"
    scipy.io.savemat(f, {"pt2d": np.zeros((2, 68))})
    with pytest.raises(HpeError, match="nopose.mat.*Pose_Para"):
        read_mat(f)


def test_inputs_untouched(tmp_path):
    copy = tmp_path / "image00251.mat"
    shutil.copy(AFLW / "image00251.mat", copy)
    before = copy.read_bytes()
    read_mat(copy)
    assert copy.read_bytes() == before
