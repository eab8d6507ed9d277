"""The kernels added to speed up ``hpe evaluate``'s protocols, against SciPy or the code they replace.

Every new kernel is compared with an independent oracle: SciPy's ``Rotation`` where the peer calls it, or
the previous implementation kept here verbatim. Rotation vectors and angles cover the whole range (tiny
angles below SciPy's 1e-3 rad Taylor branch, angles near pi, gimbal lock).
"""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.metrics import peer_angles as pa_
from hpe_cli.metrics import scipy_columns as sc


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-1, 1, allow_nan=False), min_size=3, max_size=3),
    st.sampled_from([1e-12, 1e-6, 5e-4, 1e-3, 1.0000001e-3, 0.1, 1.0, 3.0, np.pi - 1e-9, np.pi]),
)
def test_matrix_from_rotvec_equals_scipy(axis, angle):
    a = np.asarray(axis)
    nrm = np.linalg.norm(a)
    v = a / nrm * angle if nrm > 1e-6 else np.array([angle, 0.0, 0.0])
    np.testing.assert_allclose(pa_.matrix_from_rotvec(v), Rotation.from_rotvec(v).as_matrix(), rtol=0, atol=2e-16)


def _old_karcher(deltas, start, tol=1e-4):
    """The quaternion Karcher mean before the column kernels: BLAS ``@`` on (N, 4) rows and SciPy's from_rotvec."""
    n = len(deltas)
    mean = pa_.stack3(sc.matrix_from_quat(tuple(np.asarray(deltas[start], dtype=np.float64)[:, None])))[0]
    for _ in range(100_000):
        x, y, z, w = (float(v[0]) for v in sc.quat_from_matrix(mean[None]))
        x, y, z = -x, -y, -z
        left = np.array([[w, -z, y, x], [z, w, -x, y], [-y, x, w, z], [-x, -y, -z, w]])
        r = np.asarray(deltas, dtype=np.float64) @ left.T
        v = sc.rotvec_from_quat((r[:, 0], r[:, 1], r[:, 2], r[:, 3]))
        d = v.sum(axis=0) / n
        if np.linalg.norm(d) < tol:
            break
        mean = mean @ Rotation.from_rotvec(d).as_matrix()
    return mean


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 3000), st.sampled_from([1, 2, 3]))
def test_karcher_equals_old_code_whatever_the_threads(seed, n, threads):
    rng = np.random.default_rng(seed)
    rv = rng.normal(0, 0.3, (n, 3)) + rng.normal(0, 0.2, 3)
    q = Rotation.from_rotvec(rv).as_quat()
    start = int(rng.integers(n))
    old = _old_karcher(q, start)
    one = pa_.opal23_karcher(q, start=start, chunk=1000)
    np.testing.assert_allclose(one, old, rtol=0, atol=1e-12)
    saved = pa_.KARCHER_PIECE
    try:
        pa_.KARCHER_PIECE = 64  # many pieces: the pool's order must not matter
        with ThreadPoolExecutor(threads) as pool:
            a = pa_.opal23_karcher(q, start=start, chunk=1000, mapper=pool.map)
        b = pa_.opal23_karcher(q, start=start, chunk=1000)
    finally:
        pa_.KARCHER_PIECE = saved
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a, old, rtol=0, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.booleans())
def test_opal23_near_mask_is_the_mask_of_near_quats(seed, grid):
    rng = np.random.default_rng(seed)
    g = rng.uniform(-180, 180, (500, 3))
    p = g + rng.normal(0, 60, g.shape)
    if grid:  # multiples of 45 degrees: rows exactly 90 degrees off, where rounding decides
        g, p = np.round(g / 45) * 45, np.round(p / 45) * 45
    A, P = pa_.opal23_matrices(g), pa_.opal23_matrices(p)
    np.testing.assert_array_equal(pa_.opal23_near_mask(A, P), pa_.opal23_near_quats(A, P)[1])
