"""SciPy ``Rotation``'s conversions as column kernels: the same arithmetic, no ``Rotation`` object per chunk.

The peers' evaluation code (opal23, opentrack, img2pose, HeadPose+) goes through
``scipy.spatial.transform.Rotation``: ``from_euler``, ``from_matrix``,
``as_euler``, ``as_matrix``, ``as_rotvec``. Each function here repeats the
arithmetic of SciPy's own implementation (scipy/scipy@v1.17.1
``scipy/spatial/transform/_rotation_xp.py``: ``_from_matrix_orthogonal``
86-153, ``from_euler`` 189-221 with ``_elementary_quat_compose`` 1032-1046 and
``compose_quat`` 1111-1124, ``as_matrix`` 299-330, ``as_rotvec`` 333-351,
``as_euler`` 362-398 with ``_get_angles`` 1049-1108; the Cython backend that
NumPy arrays use computes the same expressions row by row) on whole 1-D
columns, so the angles agree with SciPy's to the last bit (tested
against SciPy over the whole angle range, gimbal lock included, in
``tests/metrics/test_scipy_columns.py``). Where SciPy's Cython backend differs
from its array-API one, the Cython one is followed (the wrap of an angle into
[-pi, pi] keeps +pi).

Rotations are 3x3 nested lists of 1-D arrays (``R[i][j]``, see
:mod:`hpe_cli.rotation.soa`) or ``(N, 3, 3)`` arrays; quaternions are tuples
``(x, y, z, w)`` of 1-D arrays (SciPy's scalar-last order).
"""

from __future__ import annotations

import numpy as np

from .. import native
from ..native import sin_cos

#: SciPy's gimbal-lock threshold on the middle angle (radians), ``_get_angles``
_EPS = 1e-7
_AXIS = {"x": 0, "y": 1, "z": 2}


def nested(R) -> list:
    """A nested 3x3 list of columns (returned as is) or an ``(N, 3, 3)`` array as one."""
    if isinstance(R, (list, tuple)):
        return R
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    return [[R[:, i, j] for j in range(3)] for i in range(3)]


def _orthogonal(R):
    """``R`` with the rows SciPy's ``from_matrix`` would project (Gram matrix off the identity) replaced by
    ``U V^T`` of their SVD, as SciPy does (``from_matrix``, ``_rotation_xp.py``:48-83)."""
    n = int(np.broadcast(*[x for row in R for x in row]).shape[0])
    R = [[np.broadcast_to(np.asarray(x, dtype=np.float64), (n,)) for x in row] for row in R]
    ok = np.ones(n, dtype=bool)
    g, t, b = np.empty(n), np.empty(n), np.empty(n, dtype=bool)
    for i in range(3):
        for j in range(i, 3):  # in place: g = R[i][0] R[j][0] + R[i][1] R[j][1] + R[i][2] R[j][2]
            np.multiply(R[i][0], R[j][0], out=g)
            g += np.multiply(R[i][1], R[j][1], out=t)
            g += np.multiply(R[i][2], R[j][2], out=t)
            e = 1.0 if i == j else 0.0
            if e:
                g -= e
            np.abs(g, out=g)
            ok &= np.less_equal(g, 1e-12 + 1e-5 * e, out=b)  # np.isclose(g, e, atol=1e-12); NaN is not ok
    off = ~ok
    if not off.any():
        return R
    idx = np.flatnonzero(off)
    M = np.stack([np.stack([R[i][j][idx] for j in range(3)], -1) for i in range(3)], -2)
    with np.errstate(all="ignore"):
        good = np.isfinite(M).all(axis=(1, 2))
        U, _, Vt = np.linalg.svd(np.where(good[:, None, None], M, np.eye(3)))
        M = np.where(good[:, None, None], U @ Vt, np.nan)
    R = [[np.array(x) for x in row] for row in R]
    for i in range(3):
        for j in range(3):
            R[i][j][idx] = M[:, i, j]
    return R


def quat_from_matrix(R, assume_valid: bool = False) -> tuple:
    """SciPy ``Rotation.from_matrix(R).as_quat()`` (Markley's method, normalised), column-wise.

    Parameters
    ----------
    R : nested 3x3 list of 1-D arrays or ndarray (N, 3, 3)
        Rotation matrices (det > 0; rows that are not orthonormal to 1e-12
        are first projected as SciPy does).
    assume_valid : bool
        Skip that check (SciPy's ``from_matrix(assume_valid=True)``): for
        matrices built by these kernels (products of unit quaternions'
        matrices), orthonormal to a few ulp by construction.

    Returns
    -------
    tuple of 4 ndarray (N,)
        ``(x, y, z, w)``, unit norm.
    """
    R = nested(R) if assume_valid else _orthogonal(nested(R))
    r00, r01, r02 = R[0]
    r10, r11, r12 = R[1]
    r20, r21, r22 = R[2]
    tr = r00 + r11 + r22
    # SciPy takes the case of the largest of (r00, r11, r22, trace), the first one on ties (argmax)
    c0 = (r00 >= r11) & (r00 >= r22) & (r00 >= tr)
    c1 = ~c0 & (r11 >= r22) & (r11 >= tr)
    c2 = ~(c0 | c1) & (r22 >= tr)
    x, y, z, w = r21 - r12, r02 - r20, r10 - r01, 1 + tr  # the trace's case, then the rows of the others
    for case, k in ((c0, 0), (c1, 1), (c2, 2)):
        idx = np.flatnonzero(case)
        if not len(idx):
            continue
        R_ = [[np.broadcast_to(v, tr.shape)[idx] for v in row] for row in R]
        t = tr[idx]
        d = (R_[2][1] - R_[1][2], R_[0][2] - R_[2][0], R_[1][0] - R_[0][1])
        s = {(0, 1): R_[1][0] + R_[0][1], (0, 2): R_[2][0] + R_[0][2], (1, 2): R_[2][1] + R_[1][2]}
        for m, col in enumerate((x, y, z)):
            col[idx] = 1 - t + 2 * R_[k][k] if m == k else s[(min(m, k), max(m, k))]
        w[idx] = d[k]
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    return x / norm, y / norm, z / norm, w / norm


def compose(p, q) -> tuple:
    """``p * q`` (SciPy ``compose_quat``)."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    cx = py * qz - pz * qy
    cy = pz * qx - px * qz
    cz = px * qy - py * qx
    return (
        pw * qx + qw * px + cx,
        pw * qy + qw * py + cy,
        pw * qz + qw * pz + cz,
        pw * qw - px * qx - py * qy - pz * qz,
    )


def quat_from_euler(seq: str, angles, degrees: bool = False) -> tuple:
    """SciPy ``Rotation.from_euler(seq, angles).as_quat()`` column-wise.

    Parameters
    ----------
    seq : str
        Three axes, ``"XYZ"``-style (intrinsic) or ``"xyz"``-style (extrinsic).
    angles : ndarray (N, 3)
        Radians, or degrees with ``degrees=True``.

    Returns
    -------
    tuple of 4 ndarray (N,)
    """
    a = np.asarray(angles, dtype=np.float64)
    if degrees:
        a = a * (np.pi / 180.0)
    intrinsic = seq.isupper()
    zero = np.zeros(a.shape[:-1])
    q = None
    for k, ax in enumerate(seq.lower()):
        h = a[..., k] / 2.0
        sin_h, cos_h = sin_cos(h)  # np.sin, np.cos (hpe_cli.native: one C call where it gives their bits)
        e = [zero, zero, zero, cos_h]
        e[_AXIS[ax]] = sin_h
        q = tuple(e) if q is None else (compose(q, e) if intrinsic else compose(e, q))
    return q


def quat_and_matrix_from_euler(seq: str, angles, scale) -> tuple:
    """``(quat_from_euler(seq, angles * scale), matrix_from_quat of it)``: SciPy's ``Rotation.from_euler`` and its
    ``as_quat()`` and ``as_matrix()``, with each column of ``angles`` (N, 3) first multiplied by its ``scale`` (e.g.
    the degrees' ``pi / 180`` with a sign); in one compiled loop where :func:`hpe_cli.native.quat_matrix_from_euler`
    gives these numbers (the same bits)."""
    got = native.quat_matrix_from_euler(angles, scale, [_AXIS[c] for c in seq.lower()], seq.isupper())
    if got is not None:
        return got
    q = quat_from_euler(seq, np.asarray(angles, dtype=np.float64) * np.asarray(scale, dtype=np.float64))
    return q, matrix_from_quat(q)


def matrix_from_quat(q) -> list:
    """SciPy ``Rotation.from_quat(q).as_matrix()`` for unit ``q`` as a nested 3x3 list of columns."""
    x, y, z, w = q
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return [
        [x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
        [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
        [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2],
    ]


def _seq_axes(seq: str) -> tuple:
    """``(i, j, k, sign, symmetric, intrinsic)`` of an Euler sequence, as SciPy's ``_get_angles`` reads it."""
    intrinsic = seq.isupper()
    axes = [_AXIS[c] for c in seq.lower()]
    i, j, k = axes[::-1] if intrinsic else axes
    symmetric = i == k
    if symmetric:
        k = 3 - i - j
    return i, j, k, float((i - j) * (j - k) * (k - i) // 2), symmetric, intrinsic


def euler_from_quat(q, seq: str, degrees: bool = False) -> np.ndarray:
    """SciPy ``Rotation.from_quat(q).as_euler(seq)`` column-wise (Bernardes & Viollet's quaternion method).

    At gimbal lock (middle angle within 1e-7 rad of 0 or pi for proper
    sequences such as ``"XYZ"``) the third angle is 0, as in SciPy.

    Parameters
    ----------
    q : tuple of 4 ndarray (N,)
        Unit quaternions ``(x, y, z, w)``.
    seq : str
        Three different consecutive axes, e.g. ``"XYZ"`` or ``"xyz"``.

    Returns
    -------
    ndarray (N, 3)
        Angles in seq's order, in [-pi, pi] (degrees with ``degrees=True``).
    """
    i, j, k, sign, symmetric, intrinsic = _seq_axes(seq)
    qw = q[3]
    if symmetric:
        a, b, c, d = qw, q[i], q[j], q[k] * sign
    else:
        a, b, c, d = qw - q[j], q[i] + q[k] * sign, q[j] + qw, q[k] * sign - q[i]
    half_sum = np.arctan2(b, a)
    half_diff = np.arctan2(d, c)
    mid = np.arctan2(np.hypot(c, d), np.hypot(a, b))
    mid *= 2  # in [0, pi] (or NaN): |mid| is mid, |mid - pi| is pi - mid, and no wrap is needed
    lock = (mid <= _EPS) | (mid - np.pi >= -_EPS)
    first = half_sum - half_diff
    third = half_sum + half_diff
    if lock.any():  # the angle that is not set is 0; the other takes the whole turn (SciPy's cases 1 and 2)
        case1 = mid <= _EPS
        turn = np.where(case1, 2 * half_sum, 2 * half_diff * (1 if intrinsic else -1))
        if intrinsic:  # (third, mid, first) in seq order: the first angle of seq takes the turn
            first, third = np.where(lock, 0.0, first), np.where(lock, turn, third)
        else:
            first, third = np.where(lock, turn, first), np.where(lock, 0.0, third)
    if not symmetric:
        third *= sign
        mid -= np.pi / 2
    out = np.empty((len(mid), 3))
    two_pi = 2 * np.pi
    for col, v in zip((2, 0) if intrinsic else (0, 2), (first, third)):  # into [-pi, pi], +pi kept (Cython)
        out[:, col] = v
        low, high = np.flatnonzero(v < -np.pi), np.flatnonzero(v > np.pi)
        out[low, col] = v[low] + two_pi
        out[high, col] = v[high] - two_pi
    out[:, 1] = mid
    if degrees:
        out *= 180.0 / np.pi
    return out


def euler_from_matrix(R, seq: str, degrees: bool = False, assume_valid: bool = False) -> np.ndarray:
    """SciPy ``Rotation.from_matrix(R).as_euler(seq)`` column-wise (see :func:`quat_from_matrix` and
    :func:`euler_from_quat`), in one compiled loop where :func:`hpe_cli.native.euler_from_matrix` gives these
    numbers (the same bits)."""
    R = nested(R)
    out = native.euler_from_matrix(R, _seq_axes(seq), degrees, not assume_valid)
    if out is not None:
        return out
    return euler_from_quat(quat_from_matrix(R, assume_valid), seq, degrees)


def _canonical_sign(q) -> np.ndarray:
    """+-1 per row: SciPy's ``_quat_canonical`` flips ``q`` when w < 0 (ties: the first nonzero of x, y, z)."""
    x, y, z, w = q
    flip = w < 0
    zero = w == 0
    if zero.any():
        flip |= zero & ((x < 0) | ((x == 0) & ((y < 0) | ((y == 0) & (z < 0)))))
    return np.where(flip, -1.0, 1.0)


def quat_angle(q) -> np.ndarray:
    """Rotation angle ``2 atan2(|(x, y, z)|, |w|)`` of unit quaternions (radians, in [0, pi]): SciPy's
    ``as_rotvec`` angle, the norm of the rotation vector to float rounding."""
    x, y, z, w = q
    return 2 * np.arctan2(np.sqrt(x * x + y * y + z * z), np.abs(w))


def rotvec_from_quat(q) -> np.ndarray:
    """SciPy ``Rotation.from_quat(q).as_rotvec()`` (radians), ``(N, 3)``."""
    x, y, z, w = q
    s = _canonical_sign(q)
    angle = 2 * np.arctan2(np.sqrt(x * x + y * y + z * z), w * s)  # the canonical w is |w|
    small = angle <= 1e-3
    a2 = angle * angle
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(small, 2 + a2 / 12 + 7 * a2 * a2 / 2880, angle / np.sin(angle / 2.0)) * s
    out = np.empty((len(angle), 3))
    np.multiply(scale, x, out=out[:, 0])
    np.multiply(scale, y, out=out[:, 1])
    np.multiply(scale, z, out=out[:, 2])
    return out


def rotation_angle_from_matrix(R) -> np.ndarray:
    """``norm(Rotation.from_matrix(R).as_rotvec())`` (radians, in [0, pi]) column-wise."""
    return np.linalg.norm(rotvec_from_quat(quat_from_matrix(R)), axis=1)
