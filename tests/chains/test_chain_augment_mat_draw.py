"""Chains on the real AFLW2000-3D sample: .mat folder -> augment (hflip, rotate, crop) -> .mat -> convert, and
-> draw. Oracles: SciPy composes the expected rotation, OpenCV moves the points (getRotationMatrix2D, flip,
slicing), scipy.io reads the written files."""

import shutil

import cv2
import numpy as np
import pandas as pd
import pytest
import scipy.io
from scipy.spatial.transform import Rotation

from conftest import hpe
from hpe_cli.geometry.landmark_schemes import flip_permutation

from .conftest import COLOURS, a300wlp, geodesic_deg

STEMS = ["image00050", "image00430", "image02283"]


@pytest.fixture
def aflw(realdata, tmp_path):
    d = tmp_path / "in"
    d.mkdir()
    for s in STEMS:
        for ext in (".mat", ".jpg"):
            shutil.copy(realdata / "aflw2000_prnet" / f"{s}{ext}", d / f"{s}{ext}")
    return d


def expected(how, A, pts, size):
    """(expected canonical matrix, expected (2, L) points, output size) from SciPy and OpenCV."""
    W, H = size
    kind, arg = how
    if kind == "rotate":
        P = cv2.getRotationMatrix2D(((W - 1) / 2, (H - 1) / 2), arg, 1.0)
        q = (P[:, :2] @ pts) + P[:, 2:]
        return Rotation.from_euler("z", arg, degrees=True).as_matrix() @ A, q, (W, H)
    if kind == "hflip":
        S = np.diag([-1.0, 1.0, 1.0])
        q = np.vstack([W - 1 - pts[0], pts[1]])
        return S @ A @ S, q, (W, H)
    if kind == "scale":
        return A, (pts + 0.5) * arg - 0.5, (round(W * arg), round(H * arg))
    x, y, w, h = arg
    return A, pts - np.array([[x], [y]]), (w, h)


@pytest.mark.parametrize(
    "how,args",
    [
        (("hflip", None), ["--hflip"]),
        (("rotate", 30.0), ["--rotate", 30]),
        (("crop", (60, 40, 330, 360)), ["--crop", 60, 40, 330, 360]),
        (("scale", 0.5), ["--scale", 0.5]),
    ],
    ids=["hflip", "rotate30", "crop", "half"],
)
def test_mat_augment_mat_convert_draw(aflw, tmp_path, how, args):
    out = tmp_path / "out"
    res = hpe("augment", aflw, "-o", tmp_path / "aug.parquet", *args, "--images", aflw, "--out-images", out)
    assert res.exit_code == 0, res.output
    assert "3 .mat files written back" in res.output
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{s}{e}" for s in STEMS for e in (".jpg", ".mat"))
    res = hpe("convert", out, "-o", tmp_path / "conv.csv", "--from", "300w_lp", "--to", "300w_lp", "-q")
    assert res.exit_code == 0, res.output
    conv = pd.read_csv(tmp_path / "conv.csv").set_index("file")
    aug = pd.read_parquet(tmp_path / "aug.parquet").set_index("file")
    hidden = 0
    for s in STEMS:
        m0 = scipy.io.loadmat(str(aflw / f"{s}.mat"))
        m1 = scipy.io.loadmat(str(out / f"{s}.mat"))
        p0 = m0["Pose_Para"].reshape(-1).astype(np.float64)
        A0 = a300wlp(*np.degrees(p0[:3]))
        img0 = cv2.imread(str(aflw / f"{s}.jpg"))
        H0, W0 = img0.shape[:2]
        # the rotation, as matrices, through the .mat and convert
        pt0 = m0["pt2d"].astype(np.float64)
        A_want, pts_want, (W1, H1) = expected(how, A0, pt0, (W0, H0))
        r = conv.loc[f"{s}.mat"]
        A_conv = np.array([[r[f"r{i}{j}"] for j in range(3)] for i in range(3)])
        assert geodesic_deg(A_want, A_conv) < 1e-6
        a = aug.loc[f"{s}.mat"]
        assert geodesic_deg(A_want, a300wlp(a.pitch, a.yaw, a.roll)) < 1e-6
        # pt2d moved (a mirror re-indexes the 21 AFLW points); invisible points (x = -1, y a filler) kept as they are
        vis = pt0[0] != -1
        perm = flip_permutation("aflw21") if how[0] == "hflip" else np.arange(pt0.shape[1])
        pt1 = m1["pt2d"]
        assert np.allclose(pt1[:, vis[perm]], pts_want[:, perm][:, vis[perm]], atol=1e-9)
        assert np.array_equal(pt1[:, ~vis[perm]], pt0[:, perm][:, ~vis[perm]])
        hidden += int((~vis).sum())
        # pt3d_68: x, y move like the points, depth stays (re-indexed after a mirror)
        p3 = m0["pt3d_68"].astype(np.float64)
        _, q3, _ = expected(how, A0, p3[:2], (W0, H0))
        perm68 = flip_permutation("ibug68") if how[0] == "hflip" else np.arange(68)
        assert np.allclose(m1["pt3d_68"][:2], q3[:, perm68], atol=1e-6)
        zoom = how[1] if how[0] == "scale" else 1.0
        assert np.allclose(m1["pt3d_68"][2], p3[2][perm68] * zoom, atol=1e-6)
        # tdx, tdy (tdy from the bottom row) moved as a point
        c0 = np.array([[p0[3]], [H0 - 1 - p0[4]]])
        _, c1, _ = expected(how, A0, c0, (W0, H0))
        p1 = m1["Pose_Para"].reshape(-1)
        assert (
            np.allclose([p1[3], H1 - 1 - p1[4]], c1[:, 0], atol=1e-6)
            and np.allclose(p1[5], p0[5])
            and np.isclose(p1[6], p0[6] * zoom)
        )
        # roi: the region of the original photo; a crop shows a sub-rectangle of it
        roi0, roi1 = m0["roi"].reshape(-1).astype(float), m1["roi"].reshape(-1)
        if how[0] == "crop":
            x, y, w, h = how[1]
            sx, sy = (roi0[2] - roi0[0]) / W0, (roi0[3] - roi0[1]) / H0
            assert np.allclose(
                roi1, [roi0[0] + x * sx, roi0[1] + y * sy, roi0[0] + (x + w) * sx, roi0[1] + (y + h) * sy]
            )
        else:
            assert np.allclose(roi1, roi0)
        # the image: OpenCV's own operation on the input (JPEG re-encoding: compare loosely)
        img1 = cv2.imread(str(out / f"{s}.jpg"))
        assert img1.shape[:2] == (H1, W1)
        if how[0] == "hflip":
            ref = cv2.flip(img0, 1)
        elif how[0] == "rotate":
            ref = cv2.warpAffine(img0, cv2.getRotationMatrix2D(((W0 - 1) / 2, (H0 - 1) / 2), 30, 1.0), (W0, H0))
        elif how[0] == "scale":
            ref = cv2.resize(img0, (W1, H1), interpolation=cv2.INTER_AREA)
        else:
            x, y, w, h = how[1]
            ref = img0[y : y + h, x : x + w]
        assert np.abs(img1.astype(int) - ref.astype(int)).mean() < 3
    assert (
        hidden > 0
    )  # the sample has invisible points: they were kept    # -> draw the written-back folder: lines from the moved centre, ends where SciPy puts them, inside the image
    res = hpe("draw", out, "-o", tmp_path / "drawn", "--thickness", "3")
    assert res.exit_code == 0, res.output
    for s in STEMS:
        m1 = scipy.io.loadmat(str(out / f"{s}.mat"))
        p1 = m1["Pose_Para"].reshape(-1)
        img = cv2.imread(str(tmp_path / "drawn" / f"{s}.jpg"))
        H1, W1 = img.shape[:2]
        c = np.array([p1[3], H1 - 1 - p1[4]])
        A = a300wlp(*np.degrees(p1[:3]))
        L = abs(p1[6]) * 100_000
        ends = [c + L * sgn * np.array([A[0, i], -A[1, i]]) for i, sgn in enumerate((1, -1, 1))]
        inside = 0
        for i, e in enumerate(ends):
            q = c + 0.85 * (e - c)  # on the line, away from its anti-aliased cap
            if not (3 <= q[0] < W1 - 3 and 3 <= q[1] < H1 - 3) or np.hypot(*(e - c)) < 30:
                continue
            if any(
                np.hypot(*(q - (c + t * (ends[j] - c)))) < 8 for j in range(i + 1, 3) for t in np.linspace(0, 1, 50)
            ):
                continue  # a later line is drawn over this point
            inside += 1
            px = img[round(q[1]), round(q[0])].astype(int)
            assert np.abs(px - COLOURS[i]).max() < 80, (s, i, px)
        assert inside >= 1


def test_mat_folder_augment_without_image_sizes_uses_the_images(aflw, tmp_path):
    # AFLW2000 tables have no image_width/image_height: the images give 450x450
    res = hpe(
        "augment", aflw, "-o", tmp_path / "a.parquet", "--rotate", 10, "--images", aflw, "--out-images", tmp_path / "o"
    )
    assert res.exit_code == 0, res.output
    res = hpe(
        "augment",
        aflw,
        "-o",
        tmp_path / "b.parquet",
        "--rotate",
        10,
        "--images",
        aflw,
        "--out-images",
        tmp_path / "o2",
        "--image-size",
        400,
        450,
    )
    assert res.exit_code == 1 and "the image is 450x450, --image-size says 400x450" in res.output
    assert not (tmp_path / "o2").exists()
