"""Projection against cv2.projectPoints; helmet points and boxes against a naive per-point oracle."""

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.geometry.helmet import helmet_boxes, helmet_points
from hpe_cli.geometry.projection import max_valid_r2, project_points, project_points_panoptic_toolbox
from hpe_cli.geometry.reference import helmet_preset

# hd 00_00 of 160906_pizza1 (PROVENANCE.md), the rotation replaced by a random one in the tests
K0 = np.array([[1634.03, 0, 942.792], [0, 1629.73, 558.29], [0, 0, 1]])
D0 = np.array([-0.2224, 0.1992, 8.7e-5, 9.8e-4, 0.0238])


def _cv2(X, K, d, R, t):
    uv, _ = cv2.projectPoints(X.reshape(-1, 3).astype(np.float64), cv2.Rodrigues(R)[0], t.astype(np.float64), K, d)
    return uv.reshape(X.shape[:-1] + (2,))


@given(st.integers(0, 2**32 - 1))
def test_project_points_equals_opencv(seed):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    t = rng.normal(size=3) * 50
    d = np.concatenate([rng.uniform(-0.4, 0.4, 2), rng.uniform(-0.01, 0.01, 2), rng.uniform(-0.1, 0.1, 1)])
    K = np.array(
        [
            [rng.uniform(300, 3000), 0.0, rng.uniform(0, 2000)],
            [0, rng.uniform(300, 3000), rng.uniform(0, 2000)],
            [0, 0, 1],
        ]
    )
    # points in front of the camera, within about 40 degrees of the axis
    Xc = np.concatenate([rng.uniform(-0.8, 0.8, (64, 2)), np.ones((64, 1))], 1) * rng.uniform(50, 500, (64, 1))
    X = (Xc - t) @ R  # camera -> world
    uv, z = project_points(X, K, d, R, t)
    np.testing.assert_allclose(uv, _cv2(X, K, d, R, t), atol=1e-7, rtol=1e-10)
    np.testing.assert_allclose(z, Xc[:, 2], rtol=1e-12)
    # cv2.projectPoints ignores a skew K[0, 1]; the pinhole model adds skew * yd to u
    Ks = K.copy()
    Ks[0, 1] = 0.5
    uv_s, _ = project_points(X, Ks, d, R, t)
    np.testing.assert_allclose(uv_s[:, 1], uv[:, 1])
    np.testing.assert_allclose(uv_s[:, 0] - uv[:, 0], 0.5 * (uv[:, 1] - K[1, 2]) / K[1, 1], atol=1e-7)


def test_project_points_broadcasts_cameras():
    rng = np.random.default_rng(0)
    R = Rotation.random(3, random_state=1).as_matrix()
    t = np.stack([-r @ np.array([0, 0, -300.0]) for r in R])  # every camera looks at the origin
    X = rng.normal(size=(5, 3, 7, 3)) * 20  # (faces, cameras, points, 3)
    uv, _ = project_points(X, K0, D0, R[:, None], t[:, None, :, None])  # t as (3, 1) columns
    for c in range(3):
        np.testing.assert_allclose(uv[:, c], _cv2(X[:, c], K0, D0, R[c], t[c]), atol=1e-7)


def test_panoptic_toolbox_bug_is_the_reused_x():
    """The legacy projection differs from OpenCV only through 2 p2 y (x_d - x)."""
    X = np.array([[150.0, 100.0, 300.0], [-150.0, -90.0, 300.0], [0.0, 0.0, 300.0]])
    R, t = np.eye(3), np.zeros(3)
    good, _ = project_points(X, K0, D0, R, t)
    bad, _ = project_points_panoptic_toolbox(X, K0, D0, R, t)
    assert np.abs(good[:, 0] - bad[:, 0]).max() < 1e-9  # x is right in both
    x, y = X[:, 0] / X[:, 2], X[:, 1] / X[:, 2]
    r2 = x * x + y * y
    xd = x * (1 + D0[0] * r2 + D0[1] * r2**2 + D0[4] * r2**3) + 2 * D0[2] * x * y + D0[3] * (r2 + 2 * x * x)
    np.testing.assert_allclose(bad[:, 1] - good[:, 1], K0[1, 1] * 2 * D0[3] * y * (xd - x), atol=1e-9)
    assert np.abs(bad[:2, 1] - good[:2, 1]).min() > 1e-3  # visible off-centre, zero at the centre
    assert bad[2, 1] == pytest.approx(good[2, 1])
    no_p2 = D0.copy()
    no_p2[3] = 0
    assert np.allclose(project_points_panoptic_toolbox(X, K0, no_p2, R, t)[0], project_points(X, K0, no_p2, R, t)[0])


def test_max_valid_r2():
    assert max_valid_r2(np.zeros(5)) == 4.0
    # r (1 - r^2): slope 1 - 3 r^2 vanishes at r^2 = 1/3
    assert max_valid_r2(np.array([-1.0, 0, 0, 0, 0])) == pytest.approx(1 / 3, abs=2e-3)
    assert max_valid_r2(D0) > 0.6  # a real HD lens is monotonic over its whole image (r^2 ~ 0.47)


def test_helmet_points():
    pts = helmet_points(22)
    assert pts.shape == (648, 3)
    # WHENet's get_sphere order: theta outer (0..350), phi inner (0..170); offset (0, 5, -5)
    np.testing.assert_allclose(pts[0], [0, 5, 22 - 5])
    th, ph = np.deg2rad(10), np.deg2rad(20)
    np.testing.assert_allclose(
        pts[18 + 2], 22 * np.array([np.cos(th) * np.sin(ph), np.sin(th) * np.sin(ph), np.cos(ph)]) + [0, 5, -5]
    )
    np.testing.assert_allclose(np.linalg.norm(pts - [0, 5, -5], axis=1), 22)
    assert np.allclose(helmet_points(18, (0, 0, 0)).mean(0)[:2], 0, atol=1e-12)


def test_presets():
    w, d = helmet_preset("whenet"), helmet_preset("directmhp")
    assert (w.radius, w.max_aspect, w.aspect_inclusive, w.check_height) == (22, 2.0, True, False)
    assert (d.radius, d.max_aspect, d.aspect_inclusive, d.max_side_fraction, d.check_height) == (
        18,
        1.5,
        False,
        0.7,
        True,
    )
    with pytest.raises(ValueError, match="helmet preset"):
        helmet_preset("hopenet")


def _naive_boxes(s, R, t, K, d, cR, ct, W, H, radius):
    """Every helmet point through cv2.projectPoints, then min/max clamped to the image."""
    out = []
    for n in range(len(s)):
        pts = s[n] * helmet_points(radius) @ R[n].T + t[n]
        uv = _cv2(pts, K, d, cR, ct)
        x0, y0 = max(uv[:, 0].min(), 0), max(uv[:, 1].min(), 0)
        x1, y1 = min(uv[:, 0].max(), W), min(uv[:, 1].max(), H)
        out.append([x0, y0, x1 - x0, y1 - y0])
    return np.array(out)


@pytest.mark.parametrize("preset", ["whenet", "directmhp"])
def test_helmet_boxes_match_naive_projection(preset):
    rng = np.random.default_rng(7)
    n = 60
    cR = Rotation.from_euler("xyz", [5, -20, 2], degrees=True).as_matrix()
    ct = np.array([10.0, -5.0, 280.0])
    R = Rotation.random(n, random_state=8).as_matrix()
    s = rng.uniform(0.85, 1.05, n)
    # heads spread over the field of view (some across the border), 150-400 cm away
    Xc = np.concatenate([rng.uniform(-0.7, 0.7, (n, 1)), rng.uniform(-0.45, 0.45, (n, 1)), np.ones((n, 1))], 1)
    Xc *= rng.uniform(150, 400, (n, 1))
    t = (Xc - ct) @ cR
    out = helmet_boxes(s, R, t, K0, D0, cR, ct, 1920, 1080, preset=preset)
    ref = _naive_boxes(s, R, t, K0, D0, cR, ct, 1920, 1080, helmet_preset(preset).radius)
    valid = np.isfinite(out["bbox"]).all(1)
    assert valid.sum() >= n - 5
    np.testing.assert_allclose(out["bbox"][valid], ref[valid], atol=1e-3)  # float32 helmet, < 1e-3 px
    # the rule, re-applied to the oracle's boxes
    w, h = ref[:, 2], ref[:, 3]
    aspect = np.maximum(w / h, h / w)
    if preset == "whenet":
        rule = (w > 0) & (h > 0) & (aspect <= 2) & (w < 1920)
    else:
        rule = (w > 0) & (h > 0) & (aspect < 1.5) & (w < 0.7 * 1920) & (h < 0.7 * 1080)
    decided = out["reason"] != "outside image"
    assert np.array_equal(out["ok"][decided], rule[decided])
    assert set(out["reason"]) <= {"", "outside image", "box rejected"}


def test_helmet_reasons():
    cR, ct = np.eye(3), np.zeros(3)
    R = np.repeat(np.diag([-1.0, -1, 1])[None], 6, 0)  # the rotation only moves the helmet centre
    # a helmet centre that lands on pixel (1900, 560), just inside the right border
    xn = cv2.undistortPoints(np.array([[[1900.0, 560.0]]]), K0, D0)[0, 0]
    edge = np.array([xn[0] * 295, xn[1] * 295 + 5, 300.0])  # t = centre - R @ (0, 5, -5)
    t = np.array(
        [
            [0, 0, 300.0],  # centred: ok
            [0, 0, -300.0],  # behind the camera
            [0, 0, 10.0],  # the camera is inside the helmet
            [5000, 0, 300.0],  # far to the side, in front: outside the image
            edge,  # box cut in half by the border: aspect ~1.9
            [np.nan] * 3,  # no fit
        ]
    )
    s = np.array([1, 1, 1, 1, 1, np.nan])
    out = helmet_boxes(s, R, t, K0, D0, cR, ct, 1920, 1080)
    assert list(out["reason"]) == ["", "behind camera", "behind camera", "outside image", "", "no fit"]
    assert np.isnan(out["bbox"][1]).all() and np.isnan(out["bbox"][5]).all()
    w, h = out["bbox"][4, 2:]
    assert 1.5 < h / w <= 2  # kept by WHENet's rule (<= 2) ...
    dm = helmet_boxes(s, R, t, K0, D0, cR, ct, 1920, 1080, preset="directmhp")
    assert dm["reason"][4] == "box rejected" and dm["detail"][4] == "aspect ratio >= 1.5"  # ... not DirectMHP's
    close = helmet_boxes([1.0], R[:1], [[0, 0, 60.0]], K0, D0, cR, ct, 1920, 1080, preset="directmhp")
    assert close["reason"][0] == "box rejected" and "0.7" in close["detail"][0]
    # per-row cameras and image sizes
    per_row = helmet_boxes(
        s[:1].repeat(2),
        R[:2],
        t[[0, 0]],
        np.stack([K0, K0]),
        np.stack([D0, D0]),
        np.stack([cR, cR]),
        np.stack([ct, ct]),
        [1920, 640],
        [1080, 480],
        return_centre=True,
    )
    assert per_row["ok"][0] and not per_row["ok"][1]  # the head centre is outside a 640x480 image
    np.testing.assert_allclose(per_row["centre"][0], _cv2(np.array([[0, -5.0, 295.0]]), K0, D0, cR, ct)[0])
