"""The fast helmet box (only grid points near the tangent points are projected) against an oracle.

The oracle is the box as it was computed before the fast path: all 648 points of WHENet's helmet
grid (``helmet_points``) projected in float64 with OpenCV's model (``project_points``), min/max,
clamped. The fast path must give the same box to 0.5 px (it gives the slow path's float32 box
exactly) and the same reasons, over random heads in front of the real pizza1 HD cameras.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hpe_cli.geometry import helmet as H
from hpe_cli.geometry.projection import project_points
from hpe_cli.geometry.reference import helmet_preset


def _cameras(realdata):
    from hpe_cli.datasets import panoptic as pan

    p = realdata / "panoptic_160906_pizza1" / "calibration_160906_pizza1.json"
    return pan.read_calibration(p, "hd")


def _random_views(cams, n, seed):
    rng = np.random.default_rng(seed)
    ci = rng.integers(0, len(cams), n)
    K, d, cR, ct = cams.K[ci], cams.dist[ci], cams.R[ci], cams.t[ci]
    z = rng.uniform(60, 600, n)
    u = rng.uniform(-300, 2220, n)
    v = rng.uniform(-300, 1380, n)
    centre = np.stack([(u - K[:, 0, 2]) / K[:, 0, 0] * z, (v - K[:, 1, 2]) / K[:, 1, 1] * z, z], 1)
    Rh = Rotation.random(n, random_state=seed).as_matrix()
    s = rng.uniform(0.8, 1.2, n)
    world = np.einsum("nji,nj->ni", cR, centre - ct)
    t = world - s[:, None] * np.einsum("nij,j->ni", Rh, np.array([0.0, 5.0, -5.0]))
    return s, Rh, t, K, d, cR, ct


def _oracle(s, Rh, t, K, d, cR, ct, W, H_, preset):
    p = helmet_preset(preset)
    pts = H.helmet_points(p.radius, p.offset)  # WHENet's 648 points
    X = s[:, None, None] * np.einsum("nij,pj->npi", Rh, pts) + t[:, None]
    uv, z = project_points(X, K[:, None], d[:, None], cR[:, None], ct[:, None])
    lo, hi = uv.min(1), uv.max(1)
    x0, y0 = np.maximum(lo[:, 0], 0), np.maximum(lo[:, 1], 0)
    x1, y1 = np.minimum(hi[:, 0], W), np.minimum(hi[:, 1], H_)
    return np.stack([x0, y0, x1 - x0, y1 - y0], 1), (z > 0).all(1)


@pytest.mark.parametrize("preset", ["whenet", "directmhp"])
def test_fast_box_equals_the_full_grid(realdata, preset):
    cams = _cameras(realdata)
    args = _random_views(cams, 6000, 11 if preset == "whenet" else 12)
    W, H_ = np.full(6000, 1920.0), np.full(6000, 1080.0)
    try:
        H.FAST = False
        slow = H.helmet_boxes(*args, W, H_, preset)
    finally:
        H.FAST = True
    fast = H.helmet_boxes(*args, W, H_, preset)
    box, front = _oracle(*args, W, H_, preset)
    np.testing.assert_array_equal(fast["reason"], slow["reason"])
    both = np.isfinite(fast["bbox"]).all(1)
    assert both.sum() > 3000
    np.testing.assert_array_equal(fast["bbox"][both], slow["bbox"][both])
    ok = fast["ok"]
    assert ok.sum() > 2000
    assert np.abs(fast["bbox"][ok] - box[ok]).max() < 0.5
    # most views take the fast path
    c_small = np.isfinite(fast["bbox"]).all(1)
    assert c_small.mean() > 0.5


def test_table_neighbourhoods_cover_the_grid():
    T = H._table()
    assert T["counts"].min() >= 1
    th, ph = H._grid_angles()
    U = np.stack([np.cos(th) * np.sin(ph), np.sin(th) * np.sin(ph), np.cos(ph)], 1)
    # brute force for a few bins: the table equals the points within the neighbourhood radius
    rng = np.random.default_rng(0)
    for b in rng.integers(0, T["nt"] * T["nphi"], 50):
        ti, pi = divmod(int(b), T["nphi"])
        t_c, p_c = np.deg2rad((ti + 0.5) * H.FAST_BIN), np.deg2rad((pi + 0.5) * H.FAST_BIN)
        c = np.array([np.cos(t_c) * np.sin(p_c), np.sin(t_c) * np.sin(p_c), np.cos(p_c)])
        want = np.flatnonzero(U @ c >= np.cos(np.deg2rad(H.FAST_NEIGHBOURHOOD + H.FAST_BIN)))
        got = T["indices"][T["offsets"][b] : T["offsets"][b + 1]]
        np.testing.assert_array_equal(np.sort(got), want)
