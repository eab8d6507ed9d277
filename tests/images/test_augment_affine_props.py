"""Property tests: the pixel affines of every augmentation equal OpenCV's own matrices, over the full angle range."""

import cv2
import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from hpe_cli.geometry.augment import move_td, pixel_affine, plane_matrix, scale_affine

sizes = st.tuples(st.integers(1, 4000), st.integers(1, 4000))
angles = st.floats(-720, 720, allow_nan=False)
points = st.lists(st.tuples(st.floats(-5000, 5000), st.floats(-5000, 5000)), min_size=1, max_size=20)


@given(angles, sizes, points)
def test_rotate_is_get_rotation_matrix_2d(phi, wh, pts):
    W, H = wh
    P = pixel_affine(plane_matrix("rotate", phi), wh)
    ref = cv2.getRotationMatrix2D(((W - 1) / 2, (H - 1) / 2), phi, 1.0)
    assert np.allclose(P, ref, atol=1e-9)
    p = np.asarray(pts, dtype=np.float64)
    got = p @ P[:, :2].T + P[:, 2]
    want = cv2.transform(p[None], ref)[0]
    assert np.allclose(got, want, atol=1e-6)


@given(sizes, st.floats(0.01, 16), points)
def test_scale_is_cv2_resize_mapping(wh, s, pts):
    """cv2.resize maps destination pixel centres as src = (dst + 0.5) / s - 0.5 (INTER_LINEAR docs)."""
    P = scale_affine(s)
    p = np.asarray(pts, dtype=np.float64)
    q = p @ P[:, :2].T + P[:, 2]
    assert np.allclose((q + 0.5) / s - 0.5, p, atol=1e-6 * (1 + np.abs(p)))


@given(sizes, st.floats(-1e4, 1e4), st.floats(-1e4, 1e4))
def test_tdy_from_the_bottom_round_trips_under_vflip(wh, tdx, tdy):
    W, H = wh
    P = pixel_affine(plane_matrix("vflip"), wh)
    x, y = move_td(np.array([tdx]), np.array([tdy]), P, H, H, True)
    # a vertical flip turns "rows from the bottom" into "rows from the top": tdy' = H - 1 - tdy
    assert np.allclose([x[0], y[0]], [tdx, H - 1 - tdy], atol=1e-6)
