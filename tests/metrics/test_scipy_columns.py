"""The column kernels that replace SciPy ``Rotation`` in the protocols, against SciPy and the old code.

``hpe_cli.metrics.scipy_columns`` repeats SciPy's arithmetic on whole columns;
here every kernel is compared with SciPy itself, and every protocol that used
to build ``Rotation`` objects per chunk (opal23, opal23-align, img2pose,
opentrack) with its previous implementation, kept below verbatim as the oracle.
Angles cover the whole [-180, 180]^3 cube, with rows at gimbal lock (middle
angle exactly +-90 for ``XYZ``/``xyz``, 0 / 180 for the peers' built matrices),
within 1e-9 deg of it, and multiples of 45 deg (ties of SciPy's case choice).
"""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.metrics import peer_angles as pa_
from hpe_cli.metrics import scipy_columns as sc
from hpe_cli.metrics.evaluate import compute_rows
from hpe_cli.metrics.protocols import PROTOCOLS
from hpe_cli.rotation.systems import get_system

pytestmark = pytest.mark.filterwarnings("ignore:Gimbal lock detected")


# ------------------------------------------------------------------ the old implementations (oracles)
def _old_euler(R, seq, degrees=False):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(R).as_euler(seq, degrees=degrees)


def _old_opal23_matrices(pyr):
    a = np.asarray(pyr, dtype=np.float64) * np.array([1.0, -1.0, 1.0])
    return Rotation.from_euler("XYZ", a, degrees=True).as_matrix()


def _old_opal23_mae(ann, pred):
    a = _old_euler(ann, "XYZ", True)
    p = _old_euler(pred, "XYZ", True)
    a[:, [0, 1]] = a[:, [1, 0]]
    p[:, [0, 1]] = p[:, [1, 0]]
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


def _old_opal23_geodesic(ann, pred):
    t = np.einsum("nij,nij->n", ann, pred)
    return np.rad2deg(np.arccos(np.clip((t - 1) / 2, -1, 1)))


def _old_near(ann, pred):
    deltas = np.matmul(pred, np.transpose(ann, (0, 2, 1)))
    near = np.linalg.norm(Rotation.from_matrix(deltas).as_rotvec(), axis=1) < np.pi / 2
    return deltas[near], near


def _old_img2pose_euler(R):
    return _old_euler(np.transpose(R, (0, 2, 1)), "xyz", True) * np.array([1.0, -1.0, -1.0])


def _old_opentrack_euler(T):
    return _old_euler(T, "XYZ") * np.array([1.0, -1.0, 1.0])


# ------------------------------------------------------------------ angle sets
def _angles(seed: int, n: int = 400) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = rng.uniform(-180, 180, (n, 3))
    k = n // 8
    a[:k, 1] = rng.choice([90.0, -90.0], k)  # gimbal lock of XYZ / xyz
    a[k : 2 * k, 1] = rng.choice([90.0, -90.0], k) + rng.normal(0, 1e-9, k)  # next to it
    a[2 * k : 3 * k] = np.round(a[2 * k : 3 * k] / 45.0) * 45.0  # ties between SciPy's cases
    a[3 * k : 4 * k, 1] = rng.uniform(-1e-6, 1e-6, k)  # near the identity's middle angle
    return a


def _arr(X):
    return np.stack([np.stack([np.broadcast_to(x, X[0][0].shape) for x in row], -1) for row in X], -2)


def _at_90(A, P):
    """Rows whose P A^T is within 1e-9 rad of 90 degrees (opal23's cut-off for its mean)."""
    t = np.einsum("nij,nij->n", A, P)
    return np.abs(np.arccos(np.clip((t - 1) / 2, -1, 1)) - np.pi / 2) < 1e-9


def _close_angles(a, b, tol=1e-9):
    d = np.abs(np.asarray(a) - np.asarray(b)) % 360.0
    return np.minimum(d, 360.0 - d).max() <= tol


# ------------------------------------------------------------------ kernels against SciPy
@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["XYZ", "xyz", "ZYX", "zyx", "YXZ", "yzx"]))
def test_quat_and_matrix_from_euler_equal_scipy(seed, seq):
    a = _angles(seed)
    r = Rotation.from_euler(seq, a, degrees=True)
    q = sc.quat_from_euler(seq, a, degrees=True)
    np.testing.assert_allclose(np.stack(q, -1), r.as_quat(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(_arr(sc.matrix_from_quat(q)), r.as_matrix(), rtol=0, atol=1e-15)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["XYZ", "xyz", "ZYX", "zyx", "YXZ", "yzx"]))
def test_euler_from_matrix_equals_scipy(seed, seq):
    M = Rotation.from_euler("XYZ", _angles(seed), degrees=True).as_matrix()
    got = sc.euler_from_matrix(M, seq, degrees=True)
    want = _old_euler(M, seq, True)
    assert _close_angles(got, want), np.abs(got - want).max()
    assert (np.abs(got) <= 180.0).all()
    # the rotation is right even where the split of the angles is not unique (gimbal lock; within SciPy's
    # 1e-7 rad of it the third angle is set to 0, which moves the matrix by up to that much)
    np.testing.assert_allclose(Rotation.from_euler(seq, got, degrees=True).as_matrix(), M, rtol=0, atol=2e-7)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_quat_rotvec_and_angle_equal_scipy(seed):
    M = Rotation.from_euler("ZYX", _angles(seed), degrees=True).as_matrix()
    r = Rotation.from_matrix(M)
    q = sc.quat_from_matrix(M)
    np.testing.assert_allclose(np.stack(q, -1), r.as_quat(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(sc.rotvec_from_quat(q), r.as_rotvec(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(sc.rotation_angle_from_matrix(M), r.magnitude(), rtol=0, atol=1e-14)


def test_quat_from_matrix_projects_like_scipy():
    """Matrices off orthonormal by more than 1e-12 are projected (SVD) before Markley's method, as SciPy does."""
    rng = np.random.default_rng(3)
    M = Rotation.random(50, random_state=4).as_matrix() + rng.normal(0, 1e-6, (50, 3, 3))
    np.testing.assert_allclose(np.stack(sc.quat_from_matrix(M), -1), Rotation.from_matrix(M).as_quat(), atol=1e-14)


# ------------------------------------------------------------------ peer functions against the old code
@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_opal23_kernels_equal_old_implementation(seed):
    rng = np.random.default_rng(seed)
    g = _angles(seed)
    p = g + rng.normal(0, 5, g.shape)
    p[::7] = _angles(seed + 1)[::7]  # far-off predictions (some past 90 degrees: left out of the mean)
    A_old, P_old = _old_opal23_matrices(g), _old_opal23_matrices(p)
    A, P = pa_.opal23_matrices(g), pa_.opal23_matrices(p)
    np.testing.assert_allclose(_arr(A), A_old, rtol=0, atol=1e-15)
    np.testing.assert_allclose(pa_.opal23_mae(A, P), _old_opal23_mae(A_old, P_old), rtol=0, atol=1e-9)
    # acos of the clipped trace: compared as the cosine (near 0 and 180 degrees one ulp of the trace moves the
    # angle by 1e-6 degrees, and einsum's order of the nine products is its own)
    cos = np.cos(np.radians(pa_.opal23_geodesic(A, P)))
    np.testing.assert_allclose(cos, np.cos(np.radians(_old_opal23_geodesic(A_old, P_old))), rtol=0, atol=1e-14)
    d, near = pa_.opal23_near(A, P)
    d_old, near_old = _old_near(A_old, P_old)
    tie = _at_90(A_old, P_old)  # exactly 90 degrees off (angles on a 45-degree grid): rounding decides
    np.testing.assert_array_equal(near[~tie], near_old[~tie])
    if not tie.any():
        np.testing.assert_allclose(d, d_old, rtol=0, atol=1e-15)
    mean = pa_.opal23_karcher(d)
    Pa, _ = pa_.opal23_align(A, P, mean=mean)
    np.testing.assert_allclose(_arr(Pa), np.matmul(mean.T, P_old), rtol=0, atol=1e-15)
    np.testing.assert_allclose(
        pa_.opal23_mae(A, Pa), _old_opal23_mae(A_old, np.matmul(mean.T, P_old)), rtol=0, atol=1e-9
    )


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_img2pose_and_opentrack_euler_equal_old_implementation(seed):
    M = Rotation.from_euler("XYZ", _angles(seed), degrees=True).as_matrix()
    nested = [[M[:, i, j] for j in range(3)] for i in range(3)]
    assert _close_angles(pa_.img2pose_euler(nested), _old_img2pose_euler(M))
    assert _close_angles(np.degrees(pa_.opentrack_euler(nested)), np.degrees(_old_opentrack_euler(M)))


def test_every_protocol_equals_the_scipy_path_on_a_chunk():
    """compute_rows with the kernels against the same protocols run on the old SciPy functions."""
    s300, s6 = get_system("300w_lp"), get_system("6drepnet")
    rng = np.random.default_rng(11)
    g = np.c_[rng.uniform(-99, 99, 3000), rng.uniform(-99, 99, 3000), rng.uniform(-99, 99, 3000)]
    g[:100, 1] = 90.0
    p = g + rng.normal(0, 5, g.shape)
    G = s300.to_canonical(s300.from_angles(g))
    P = s6.to_canonical(s6.from_angles(p))
    raw = {"gt": (s300, g), "pred": (s6, p)}
    new = compute_rows(P, G, s300, list(PROTOCOLS), raw)
    saved = {
        k: getattr(pa_, k)
        for k in ("opal23_matrices", "opal23_quats_and_matrices", "opal23_matrix_of_quats", "_euler", "_log")
    }
    try:  # the same protocol code on the old SciPy calls
        pa_.opal23_matrices = _old_opal23_matrices
        pa_.opal23_matrix_of_quats = lambda q: Rotation.from_quat(np.stack(q, -1)).as_matrix()
        pa_.opal23_quats_and_matrices = lambda pyr: (
            tuple(Rotation.from_euler("XYZ", np.asarray(pyr, float) * [1.0, -1.0, 1.0], degrees=True).as_quat().T),
            _old_opal23_matrices(pyr),
        )
        pa_._euler = lambda R, seq, degrees=False: _old_euler(_arr(R) if isinstance(R, list) else R, seq, degrees)
        pa_._log = lambda M: Rotation.from_matrix(_arr(M) if isinstance(M, list) else M).as_rotvec()
        old = compute_rows(P, G, s300, list(PROTOCOLS), raw)
    finally:
        for k, v in saved.items():
            setattr(pa_, k, v)
    for name in PROTOCOLS:
        a, b = new.protocols[name], old.protocols[name]
        np.testing.assert_allclose(a.err, b.err, rtol=0, atol=1e-9, err_msg=name)
        np.testing.assert_array_equal(a.keep, b.keep, err_msg=name)
        for k in a.scalars:
            np.testing.assert_allclose(a.scalars[k], b.scalars[k], rtol=0, atol=1e-6, err_msg=name)
        for k in a.counts:
            np.testing.assert_array_equal(a.counts[k], b.counts[k], err_msg=name)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_karcher_mean_of_quaternions_equals_the_matrix_one(seed):
    """opal23's Karcher mean over the deltas' quaternions (the streamed spill) equals the one over matrices."""
    rng = np.random.default_rng(seed)
    g = _angles(seed, 300)
    p = g + rng.normal(0, 8, g.shape) + np.array([3.0, -2.0, 1.0])
    p[::9] = _angles(seed + 1, 300)[::9]
    A, P = _old_opal23_matrices(g), _old_opal23_matrices(p)
    d_old, near_old = _old_near(A, P)
    q, near = pa_.opal23_near_quats(A, P)
    tie = _at_90(A, P)  # exactly 90 degrees off (angles on a 45-degree grid): rounding decides
    np.testing.assert_array_equal(near[~tie], near_old[~tie])
    if (near != near_old).any():
        q = np.stack(sc.quat_from_matrix(d_old), -1)  # the mean over the same rows
    np.testing.assert_allclose(_arr(sc.matrix_from_quat(tuple(q.T))), d_old, rtol=0, atol=1e-14)  # the same rotations
    start = int(rng.integers(len(q))) if len(q) else 0
    m_quat = pa_.opal23_karcher(q, start=start, chunk=64)
    m_mat = pa_.opal23_karcher(d_old, start=start, chunk=64)
    np.testing.assert_allclose(m_quat, m_mat, rtol=0, atol=1e-12)
