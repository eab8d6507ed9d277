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
from hpe_cli.metrics import rotation_errors as re_
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


# ------------------------------------------------------------------ rewritten in place: the old code as oracle
def _old_min_wrapped(pred, gt, with_180):
    d = np.asarray(pred, dtype=np.float64) - np.asarray(gt, dtype=np.float64)
    terms = [np.abs(d), np.abs(d + 360.0), np.abs(d - 360.0)]
    if with_180:
        terms += [np.abs(d + 180.0), np.abs(d - 180.0)]
    out = terms[0]
    for t in terms[1:]:
        out = np.minimum(out, t)
    return out


def _old_opal23_mae(a, p):
    a, p = a[:, [1, 0, 2]], p[:, [1, 0, 2]]
    sign = np.sign(p)
    w = np.stack([180 - p[:, 0], p[:, 1] - sign[:, 1] * 180, p[:, 2] - sign[:, 2] * 180], axis=1)
    w[w > 180] -= 360
    w[w < -180] += 360
    e = np.abs(a - p)
    ew = np.abs(a - w)
    use = ew.mean(axis=-1) < e.mean(axis=-1)
    e[use] = ew[use]
    e = np.minimum(e, 360 - e)
    return e[:, [1, 0, 2]]


def _old_best_of_two(p1, p2, g):
    e1, e2 = np.abs(p1 - g), np.abs(p2 - g)
    second = e2.mean(axis=-1) < e1.mean(axis=-1)
    e = np.where(second[..., None], e2, e1)
    return np.minimum(e, 360.0 - e), second


def _old_maev(P, G):
    out = []
    for j in range(3):
        p = [P[0][j], P[1][j], P[2][j]]
        g = [G[0][j], G[1][j], G[2][j]]
        dot = p[0] * g[0] + p[1] * g[1] + p[2] * g[2]
        cx = p[1] * g[2] - p[2] * g[1]
        cy = p[2] * g[0] - p[0] * g[2]
        cz = p[0] * g[1] - p[1] * g[0]
        out.append(np.arctan2(np.sqrt(cx * cx + cy * cy + cz * cz), dot) * (180.0 / np.pi))
    return np.stack(np.broadcast_arrays(*out), axis=-1)


def _old_column_acos(P, G, float32):
    dt = np.float32 if float32 else np.float64
    out = []
    for j in range(3):
        p = [np.asarray(P[i][j], dtype=dt) for i in range(3)]
        g = [np.asarray(G[i][j], dtype=dt) for i in range(3)]
        dot = (g[0] * p[0] + g[1] * p[1]) + g[2] * p[2]
        out.append(np.degrees(np.arccos(np.clip(dot, -1.0, 1.0))).astype(np.float64))
    return np.stack(np.broadcast_arrays(*out), -1)


def _old_opentrack_errors(e1, e2):
    dot = np.cos(e1) * np.cos(e2) + np.sin(e1) * np.sin(e2)
    return np.degrees(np.arccos(np.clip(dot, -1.0, 1.0))), (np.abs(dot) > 1.0).any(axis=-1)


def _hard_angles(seed, n=400):
    """Degrees over [-180, 180]^3 with gimbal lock (middle +-90), rows near it, 45-degree grids, equal pairs."""
    rng = np.random.default_rng(seed)
    g = rng.uniform(-180, 180, (n, 3))
    g[: n // 8, 1] = rng.choice([90.0, -90.0], n // 8)
    g[n // 8 : n // 4, 1] = 90.0 - 1e-9
    g[n // 4 : n // 2] = np.round(g[n // 4 : n // 2] / 45) * 45
    p = g + rng.normal(0, 10, g.shape)
    p[::5] = rng.uniform(-180, 180, (len(p[::5]), 3))
    p[1::7] = g[1::7]
    p[n // 4 : n // 2 : 2] = np.round(p[n // 4 : n // 2 : 2] / 45) * 45
    return p, g


def _bits(a, b):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.asarray(a).dtype == np.asarray(b).dtype


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_rewritten_kernels_give_the_old_bits(seed):
    p, g = _hard_angles(seed)
    for with_180 in (False, True):
        _bits(pa_.min_wrapped(p, g, with_180), _old_min_wrapped(p, g, with_180))
    _bits(pa_.opal23_mae(None, None, ann_euler=g, pred_euler=p), _old_opal23_mae(g, p))
    p2 = np.roll(p, 1, axis=0)
    best, second = re_.best_of_two_error(p, p2, g)
    old_best, old_second = _old_best_of_two(p, p2, g)
    _bits(best, old_best)
    _bits(second, old_second)
    A, B = pa_.opal23_matrices(g), pa_.opal23_matrices(p)
    _bits(re_.maev_deg(A, B), _old_maev(A, B))
    for f32 in (False, True):
        _bits(pa_.column_acos_deg(A, B, f32), _old_column_acos(A, B, f32))
    e1, e2 = np.radians(p), np.radians(g)
    new, old = pa_.opentrack_errors(e1, e2), _old_opentrack_errors(e1, e2)
    _bits(new[0], old[0])
    _bits(new[1], old[1])
