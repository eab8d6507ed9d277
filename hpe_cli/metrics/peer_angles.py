"""The angle extractions and error formulas of published evaluation code, column-wise.

Each function reproduces a few named lines of a peer's current code (the
``repo@commit file:lines`` is in its docstring). Where the peer calls SciPy's
``Rotation`` the same arithmetic runs here on whole columns
(:mod:`.scipy_columns`, tested against SciPy), so the numbers agree to the last
bits; no loop per row and no ``Rotation`` object.
"""

from __future__ import annotations

import numpy as np

from .. import native
from ..native import sin_cos
from . import scipy_columns as sc

_DEG = 180.0 / np.pi

SRC_6DREPNET_EULER = "thohemp/6DRepNet@464b2ba sixdrepnet/utils.py:165-184"
SRC_OPAL23 = "pcr-upm/opal23_headpose@78c0c45 test/evaluator.py"


def stack3(X) -> np.ndarray:
    """A nested 3x3 list of columns as an ``(N, 3, 3)`` array."""
    n = int(np.broadcast(*[x for row in X for x in row]).shape[0])
    out = np.empty((n, 3, 3))
    for i in range(3):
        for j in range(3):
            out[:, i, j] = X[i][j]
    return out


def sixdrepnet_euler(R) -> np.ndarray:
    """6DRepNet's ``compute_euler_angles_from_rotation_matrices`` (pitch, yaw, roll degrees).

    thohemp/6DRepNet@464b2ba sixdrepnet/utils.py:165-184 (the same function in
    6DRepNet360@b06e4fe sixdrepnet360/utils.py:164): ``sy = sqrt(R00^2 + R10^2)``;
    ``x = atan2(R21, R22)``, ``y = atan2(-R20, sy)``, ``z = atan2(R10, R00)``;
    rows with ``sy < 1e-6``: ``x = atan2(-R12, R11)``, ``z = 0``.
    """
    R = [[np.asarray(v, dtype=np.float64) for v in row] for row in R]
    n = int(np.broadcast(*[v for row in R for v in row]).shape[0])
    R = [[np.broadcast_to(v, (n,)) for v in row] for row in R]
    sy = np.sqrt(R[0][0] * R[0][0] + R[1][0] * R[1][0])
    out = np.empty((n, 3))
    np.arctan2(R[2][1], R[2][2], out=out[:, 0])
    np.arctan2(-R[2][0], sy, out=out[:, 1])
    np.arctan2(R[1][0], R[0][0], out=out[:, 2])
    singular = sy < 1e-6
    if singular.any():  # the peer's other branch, on its rows only
        out[singular, 0] = np.arctan2(-R[1][2][singular], R[1][1][singular])
        out[singular, 2] = 0.0
    out *= _DEG
    return out


def min_wrapped(pred, gt, with_180: bool) -> np.ndarray:
    """``min(|gt - p|, |p + 360 - gt|, |p - 360 - gt|[, |p + 180 - gt|, |p - 180 - gt|])`` per angle.

    ``with_180=False`` is 6DRepNet360's current 3-term minimum
    (thohemp/6DRepNet360@b06e4fe sixdrepnet360/test.py:188-193, since 9c1cfaf);
    ``True`` the 5-term one of 6DRepNet (sixdrepnet/test.py:137-142) and TriNet
    (chuzcjoe/TriNet@d2689de computeMAE.py:168-170).
    """
    d = np.asarray(pred, dtype=np.float64) - np.asarray(gt, dtype=np.float64)
    out = np.abs(d)
    t = np.empty_like(d)
    for shift in (360.0, -360.0, 180.0, -180.0) if with_180 else (360.0, -360.0):  # in place: no temporaries
        np.add(d, shift, out=t)
        np.abs(t, out=t)
        np.minimum(out, t, out=out)
    return out


def img2pose_euler(R_img2pose) -> np.ndarray:
    """img2pose's ``convert_to_aflw``: ``as_euler('xyz')`` of ``R.T``, as ``(x, -y, -z)`` degrees.

    vitoralbiero/img2pose@fd5473e evaluation/jupyter_notebooks/aflw_2000_3d_evaluation.ipynb
    (notebook lines 112-118; ``R`` is ``Rotation.from_rotvec`` of the predicted rotation vector).
    """

    R = R_img2pose if isinstance(R_img2pose, (list, tuple)) else sc.nested(R_img2pose)
    a = _euler([[R[j][i] for j in range(3)] for i in range(3)], "xyz", True)  # R.T: the indices swapped
    return a * np.array([1.0, -1.0, -1.0])


#: opal23's angles to SciPy's: [pitch, -yaw, roll] in radians, one product a column ((x * -1) * d is x * -d)
_OPAL23_SCALE = np.array([1.0, -1.0, 1.0]) * (np.pi / 180.0)


def opal23_quats_and_matrices(pyr) -> tuple:
    """opal23's rotations of (pitch, yaw, roll) degrees, ``Rotation.from_euler('XYZ', [pitch, -yaw, roll])``, as
    SciPy's quaternions (x, y, z, w columns) and their ``.as_matrix()`` (the nested 3x3 list of columns), in one
    pass (SciPy's arithmetic, :func:`.scipy_columns.quat_and_matrix_from_euler`)."""
    return sc.quat_and_matrix_from_euler("XYZ", pyr, _OPAL23_SCALE)


def opal23_matrix_of_quats(q) -> list:
    """``.as_matrix()`` of :func:`opal23_quats_and_matrices`' quaternions (the nested 3x3 list of columns)."""
    return sc.matrix_from_quat(q)


def opal23_matrices(pyr) -> list:
    """The matrices of :func:`opal23_quats_and_matrices`."""
    return opal23_quats_and_matrices(pyr)[1]


def opal23_euler(M) -> np.ndarray:
    """``Rotation.from_matrix(M).as_euler('XYZ', degrees=True)`` of opal23's matrices (what ``compute_mae`` reads).

    They are SciPy's matrices of unit quaternions (or products of them), orthonormal to a few ulp: SciPy's
    orthonormality check (1e-12) always passes and is skipped.
    """
    return sc.euler_from_matrix(M, "XYZ", True, assume_valid=True)


def opal23_mae(ann, pred, ann_euler=None, pred_euler=None) -> np.ndarray:
    """``Evaluator.compute_mae`` (opal23_headpose@78c0c45 test/evaluator.py:51-75, 131-139).

    ``ann`` and ``pred`` are matrices (nested or ``(N, 3, 3)``); their
    ``as_euler('XYZ')`` angles (:func:`opal23_euler`) may be passed when
    already computed. Returns (N, 3) errors in the order (pitch, yaw, roll);
    the peer's array is (yaw, pitch, roll) after its ``PYR -> YPR`` swap.
    """

    a = opal23_euler(ann) if ann_euler is None else ann_euler
    p = opal23_euler(pred) if pred_euler is None else pred_euler
    got = native.opal23_mae(a, p)  # one C loop where built (no C library function: the same bits)
    if got is not None:
        return got
    # column by column in the peer's (yaw, pitch, roll) order: its row means are ((yaw + pitch) + roll) / 3
    order = (1, 0, 2)
    pc = [p[:, k] for k in order]
    ac = [a[:, k] for k in order]
    w = [180 - pc[0], pc[1] - np.sign(pc[1]) * 180, pc[2] - np.sign(pc[2]) * 180]
    for k in range(3):
        w[k] = np.where(w[k] > 180, w[k] - 360, w[k])
        w[k] = np.where(w[k] < -180, w[k] + 360, w[k])
    e = [np.abs(ac[k] - pc[k]) for k in range(3)]
    ew = [np.abs(ac[k] - w[k]) for k in range(3)]
    use = ((ew[0] + ew[1]) + ew[2]) / 3 < ((e[0] + e[1]) + e[2]) / 3
    out = np.empty((len(use), 3))
    for k, col in enumerate(order):
        x = np.where(use, ew[k], e[k])
        np.minimum(x, 360 - x, out=out[:, col])
    return out


def opal23_geodesic(ann, pred) -> np.ndarray:
    """``Evaluator.compute_ge`` (test/evaluator.py:77-93): ``arccos(clip((trace(A P^T) - 1) / 2))`` degrees."""
    A, P = sc.nested(ann), sc.nested(pred)
    got = native.trace_acos_deg(A, P)
    if got is not None:
        return got
    t = A[0][0] * P[0][0]
    for i, j in ((0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (2, 2)):
        t = t + A[i][j] * P[i][j]  # einsum's order: row by row
    return np.rad2deg(np.arccos(np.clip((t - 1) / 2, -1, 1)))


def _euler(R, seq: str, degrees: bool = False) -> np.ndarray:
    """SciPy ``Rotation.from_matrix(R).as_euler(seq)`` (column kernels of the same arithmetic, no warning)."""
    return sc.euler_from_matrix(R, seq, degrees)


def _log(M) -> np.ndarray:
    """SciPy ``Rotation.from_matrix(M).as_rotvec()`` (radians), column-wise."""
    return sc.rotvec_from_quat(sc.quat_from_matrix(M))


def _times_transpose(P, G) -> list:
    """``P @ G.T`` of nested matrices (``matmul``'s sum order per entry)."""
    return [[(P[i][0] * G[j][0] + P[i][1] * G[j][1]) + P[i][2] * G[j][2] for j in range(3)] for i in range(3)]


def opal23_near(ann, pred):
    """``(P_i A_i^T of the rows within 90 degrees of the identity as (M, 3, 3), mask of those rows)``."""
    deltas = _times_transpose(sc.nested(pred), sc.nested(ann))
    near = sc.rotation_angle_from_matrix(deltas) < np.pi / 2
    return stack3([[x[near] for x in row] for row in deltas]), near


def opal23_near_quats(ann, pred):
    """:func:`opal23_near` with the deltas as SciPy's unit quaternions ``(M, 4)`` (x, y, z, w): what the
    Karcher mean needs, in 4 numbers a row instead of 9."""
    got = native.near_quats(sc.nested(pred), sc.nested(ann))
    if got is not None:
        return got[0][got[1]], got[1]
    q = sc.quat_from_matrix(_times_transpose(sc.nested(pred), sc.nested(ann)), assume_valid=True)
    near = sc.quat_angle(q) < np.pi / 2
    return np.stack([c[near] for c in q], -1), near


def opal23_near_mask(ann, pred) -> np.ndarray:
    """The mask of :func:`opal23_near_quats` alone (rows within 90 degrees of the identity), without gathering
    their quaternions: what a chunk needs once the mean is known."""
    got = native.near_quats(sc.nested(pred), sc.nested(ann))
    if got is not None:
        return got[1]
    q = sc.quat_from_matrix(_times_transpose(sc.nested(pred), sc.nested(ann)), assume_valid=True)
    return sc.quat_angle(q) < np.pi / 2


def opal23_near_deltas(ann, pred) -> np.ndarray:
    """``P_i A_i^T`` of the rows within 90 degrees of the identity: what opal23's mean is taken over."""
    return opal23_near(ann, pred)[0]


#: rows of the Karcher mean's pieces: every piece's sums are taken alone and added in order, so the mean
#: does not depend on how many threads compute them
KARCHER_PIECE = 1 << 16


def _displacement_sum(q, left) -> np.ndarray:
    """Sum over the rows of ``log(q_mean^-1 q_i)`` (radians, 3,) for quaternions ``q`` (4, m) (columns x, y, z,
    w), ``left`` the 4x4 matrix of the left product by ``q_mean^-1``."""
    v = native.quat_rotvecs(q, left)  # one C loop where built (the same bits)
    if v is None:
        r = [((left[i, 0] * q[0] + left[i, 1] * q[1]) + left[i, 2] * q[2]) + left[i, 3] * q[3] for i in range(4)]
        v = sc.rotvec_from_quat(tuple(r))
    return np.array([v[:, k].sum() for k in range(3)])


def opal23_karcher(
    deltas, tol: float = 1e-4, max_iter: int = 100_000, chunk: int = 1 << 20, start: int = 0, mapper=map
) -> np.ndarray:
    """opal23's ``_compute_mean_rotation`` (test/evaluator.py:111-126) over ``deltas`` (any array-like, e.g. a memmap).

    ``deltas`` are matrices ``(N, 3, 3)`` or their unit quaternions ``(N, 4)``
    (:func:`opal23_near_quats`; then ``log(mean.T @ M_i)`` is taken of the
    quaternion product, the same rotation to float rounding, without a
    matrix product and a matrix-to-quaternion conversion per row and
    iteration). Started at delta ``start`` (the peer starts at the first row
    of its file: a caller that spills the deltas in another order names that
    row), ``mean <- mean @ exp(mean displacement)`` until the mean
    displacement ``log(mean.T @ M_i)`` is shorter than ``tol``; the sums run
    chunk by chunk, so a spill of any length read piece by piece (anything with
    ``len``, ``ndim`` and slicing) works. ``mapper`` (``map`` by default, e.g. a thread pool's ``map``,
    which must yield in order) computes the quaternion pieces' sums (:data:`KARCHER_PIECE` rows each), added
    in order: the same mean whatever the pool.
    """
    n = len(deltas)
    if not n:
        return np.eye(3)
    quats = (deltas.ndim if hasattr(deltas, "ndim") else np.ndim(deltas)) == 2
    if quats:
        mean = stack3(sc.matrix_from_quat(tuple(np.asarray(deltas[start], dtype=np.float64)[:, None])))[0]
    else:
        mean = np.array(deltas[start], dtype=np.float64)
    for _ in range(max_iter):
        total = np.zeros(3)
        if quats:  # mean.T @ M_i as the quaternion product inv(q_mean) q_i: one 4x4 matrix for all rows
            x, y, z, w = (float(v[0]) for v in sc.quat_from_matrix(mean[None]))
            x, y, z = -x, -y, -z
            left = np.array([[w, -z, y, x], [z, w, -x, y], [-y, x, w, z], [-x, -y, -z, w]])
        for a in range(0, n, chunk):
            if quats:  # columns x, y, z, w of the chunk, then its cache-sized pieces
                q = np.ascontiguousarray(np.asarray(deltas[a : min(a + chunk, n)], dtype=np.float64).T)
                pieces = (q[:, b : b + KARCHER_PIECE] for b in range(0, q.shape[1], KARCHER_PIECE))
                for part in mapper(lambda piece: _displacement_sum(piece, left), pieces):
                    total += part
            else:
                total += _log(np.matmul(mean.T, np.asarray(deltas[a : a + chunk]))).sum(axis=0)
        d = total / n
        if np.linalg.norm(d) < tol:
            break
        mean = mean @ matrix_from_rotvec(d)
    return mean


def matrix_from_rotvec(v) -> np.ndarray:
    """SciPy ``Rotation.from_rotvec(v).as_matrix()`` of one rotation vector ``v`` (3,), radians: its arithmetic
    (``_rotation_xp.py`` ``from_rotvec``: the half-angle's Taylor series below 1e-3 rad), no SciPy import."""
    v = np.asarray(v, dtype=np.float64)
    angle = float(np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 0.5 - a2 / 48 + a2 * a2 / 3840
    else:
        scale = np.sin(angle / 2) / angle
    q = tuple(np.array([c]) for c in (v[0] * scale, v[1] * scale, v[2] * scale, np.cos(angle / 2)))
    return stack3(sc.matrix_from_quat(q))[0]


def opal23_align(ann, pred, tol: float = 1e-4, max_iter: int = 100_000, mean=None):
    """``Evaluator.align_predictions`` with ``mask=None`` (test/evaluator.py:95-129).

    The Karcher mean of ``P_i A_i^T`` over the rows within 90 degrees of the
    identity (``distances < pi/2``), started at the first such row and
    iterated until the mean displacement is below ``tol``; every prediction
    becomes ``mean.T @ P_i``. ``mean`` given (from all chunks of a streamed
    run) skips the estimate. Returns ``(aligned predictions, mean)``.
    """
    if mean is None:
        mean = opal23_karcher(opal23_near_quats(ann, pred)[0], tol, max_iter)
    P = sc.nested(pred)
    m = np.asarray(mean, dtype=np.float64)
    return [[(m[0, i] * P[0][j] + m[1, i] * P[1][j]) + m[2, i] * P[2][j] for j in range(3)] for i in range(3)], mean


def trinet_euler(T) -> np.ndarray:
    """TriNet's ``W300_R2EulerAngles`` (chuzcjoe/TriNet@d2689de computeMAE.py:84-89), degrees.

    ``yaw = -arcsin(R02)``, ``roll = atan2(-R01, R00)``, ``pitch = atan2(-R12, R22)``
    on the matrix whose columns are the [left | down | front] vectors.
    """
    yaw = -np.arcsin(np.clip(T[0][2], -1.0, 1.0))
    roll = np.arctan2(-T[0][1], T[0][0])
    pitch = np.arctan2(-T[1][2], T[2][2])
    return np.stack(np.broadcast_arrays(pitch, yaw, roll), -1) * _DEG


def column_acos_deg(P, G, float32: bool = False) -> np.ndarray:
    """``acos(clip(sum(g_k * p_k), -1, 1))`` for the three columns k, degrees (TriNet computeMAE.py:163-165).

    ``float32=True`` computes the dot products and ``acos`` in float32, as
    6DRepNet360's test.py:181-186 does on its float32 tensors (near 0 degrees
    ``acos`` of a float32 dot product differs from the float64 one by up to
    0.02 degrees per row, which moves the mean by 1e-4 degrees).
    """
    dt = np.float32 if float32 else np.float64
    n = int(np.broadcast(*[x for row in P for x in row], *[x for row in G for x in row]).shape[0])
    out = np.empty((n, 3))
    for j in range(3):
        p = [np.broadcast_to(np.asarray(P[i][j], dtype=dt), (n,)) for i in range(3)]
        g = [np.broadcast_to(np.asarray(G[i][j], dtype=dt), (n,)) for i in range(3)]
        dot = g[0] * p[0]
        t = g[1] * p[1]
        dot += t
        dot += np.multiply(g[2], p[2], out=t)  # (g0 p0 + g1 p1) + g2 p2, in place
        np.clip(dot, -1.0, 1.0, out=dot)
        np.arccos(dot, out=dot)
        out[:, j] = np.degrees(dot, out=dot)  # float32 -> float64 on the copy, as astype does
    return out


def opentrack_euler(T) -> np.ndarray:
    """opentrack's ``inv_aflw_rotation_conversion`` (radians; pitch, yaw, roll).

    opentrack/neuralnet-tracker-traincode@8d2478c trackertraincode/utils.py:41-62:
    the rotation is ``P from_euler('XYZ', [p, -y, r]) P`` (P = diag(1, 1, -1)); its
    inverse takes ``as_euler('XYZ')`` of ``P M P`` (the [p, -y, r] matrix ``T``
    here) and negates yaw.
    """
    return _euler(T, "XYZ") * np.array([1.0, -1.0, 1.0])


def opentrack_errors(e1, e2):
    """``_angle_errors`` (trackertraincode/eval.py:337-341) with the ``arccos`` argument clipped.

    The peer computes ``arccos(cos a cos b + sin a sin b)`` without clipping,
    which is NaN where rounding puts the argument above 1. Returns the clipped
    errors (degrees) and the mask of rows the peer turns into NaN.
    """
    got = native.wrapped_cos_errors(e1, e2)
    if got is not None:
        return got
    t, dot = sin_cos(e1)  # np.sin, np.cos (hpe_cli.native: one C call where it gives their bits)
    s2, c2 = sin_cos(e2)
    dot *= c2
    t *= s2
    dot += t  # cos a cos b + sin a sin b, in place
    peer_nan = (np.abs(dot, out=t) > 1.0).any(axis=-1)
    np.clip(dot, -1.0, 1.0, out=dot)
    np.arccos(dot, out=dot)
    return np.degrees(dot, out=dot), peer_nan
