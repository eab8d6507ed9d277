"""Euler angles <-> matrices for all 12 axis sequences, both solutions, batched.

Conventions
-----------
Every function here works with **right-handed, active, intrinsic** sequences in
radians: ``seq="xyz"`` with angles ``(a, b, c)`` means ``Rx(a) @ Ry(b) @ Rz(c)``.
An extrinsic sequence is the reversed intrinsic one (with the angles reversed),
and a left-handed turn is a negated angle; :mod:`hpe_cli.rotation.systems`
applies both so that these kernels stay small.

Both solutions
--------------
Away from gimbal lock every rotation has exactly two triples. For Tait-Bryan
sequences (three distinct axes) they are ``(a, b, c)`` with ``|b| <= pi/2`` and
``(a + pi, pi - b, c + pi)``; for proper Euler sequences (``"zxz"`` ...) they
are ``(a, b, c)`` with ``0 <= b <= pi`` and ``(a + pi, -b, c + pi)``. All angles
are returned wrapped to ``(-pi, pi]``.

Gimbal lock
-----------
The lock is where the middle turn aligns the first and the last axes
(``cos b = 0`` for Tait-Bryan, ``sin b = 0`` for proper Euler). There, only
``a + sigma * c`` is observable. ``lock_distance`` returns ``|cos b|`` (or
``|sin b|``). Near the lock the textbook atan2 formulas get ``a`` and ``c``
each from entries of size ``cos b``, so their sum carries an error of about
``eps / cos b`` and the rebuilt matrix drifts (1e-7 at 1e-9 degrees from the
lock). Rows with ``lock_distance < REFINE_BELOW`` therefore take ``b`` and
``c`` from the formulas and solve ``a`` from the residual
``R @ Rk(c).T @ Rj(b).T``, which absorbs the error of ``c``: the rebuild stays
at machine precision all the way to the lock. Rows with
``lock_distance < SPLIT_EPS`` are at the lock for all numerical purposes and
are decomposed with ``a = sigma * c`` (each half of the observable sum), as
the method paper does. Callers flag rows inside their own, larger,
``gimbal_tol`` as locked.
"""

from __future__ import annotations

import numpy as np

from . import soa
from .elemental import axis_rotation

#: below this |cos b| the ordinary atan2 formulas lose all precision in float64
SPLIT_EPS = 1e-12
#: below this |cos b| the first angle is solved from the residual (within ~2.9 deg of the lock)
REFINE_BELOW = 0.05

_AXIS = {"x": 0, "y": 1, "z": 2}


def parse_seq(seq: str) -> tuple[int, int, int]:
    """Return the axis indices of a 3-letter sequence such as ``"xyz"``.

    Raises ``ValueError`` for anything that is not a valid Euler sequence.
    """
    s = seq.lower()
    if len(s) != 3 or any(ch not in _AXIS for ch in s) or s[0] == s[1] or s[1] == s[2]:
        raise ValueError(f"expected an Euler sequence such as 'xyz' or 'zxz', got {seq!r}")
    return _AXIS[s[0]], _AXIS[s[1]], _AXIS[s[2]]


def _wrap(x, half):
    x = np.asarray(x, dtype=np.float64)
    w = x - 2 * half * np.ceil((x - half) / (2 * half))
    # the subtraction can round one ulp past either end; fold those back
    w = np.where(w > half, w - 2 * half, w)
    return np.where(w <= -half, w + 2 * half, w)


def wrap_pi(x):
    """Wrap radians into ``(-pi, pi]``."""
    return _wrap(x, np.pi)


def wrap_180(x):
    """Wrap degrees into ``(-180, 180]``."""
    return _wrap(x, 180.0)


def euler_to_matrix(angles, seq: str) -> np.ndarray:
    """Intrinsic right-handed Euler angles (radians, ``(..., 3)``) to matrices ``(..., 3, 3)``."""
    angles = np.asarray(angles, dtype=np.float64)
    if angles.shape[-1:] != (3,):
        raise ValueError(f"expected angles of shape (..., 3), got {angles.shape}")
    flat = angles.reshape(-1, 3)
    X = euler_to_soa(flat[:, 0], flat[:, 1], flat[:, 2], seq)
    return soa.to_array(X, flat.shape[0]).reshape(angles.shape[:-1] + (3, 3))


def euler_to_soa(a, b, c, seq: str):
    """Like :func:`euler_to_matrix` for three 1-D angle arrays, as a nested-list matrix."""
    i, j, k = parse_seq(seq)
    return soa.mul(soa.mul(soa.elemental(i, a), soa.elemental(j, b)), soa.elemental(k, c))


def parity(i: int, j: int, k: int) -> float:
    """+1 for a cyclic sequence of axes (x, y, z order), -1 otherwise."""
    return 1.0 if (j - i) % 3 == 1 else -1.0


def lock_distance(R, seq: str) -> np.ndarray:
    """``|cos b|`` (Tait-Bryan) or ``|sin b|`` (proper Euler): 0 at gimbal lock."""
    R = np.asarray(R, dtype=np.float64)
    i, j, k = parse_seq(seq)
    if i == k:
        m = 3 - i - j
        return np.hypot(R[..., i, j], R[..., i, m])
    return np.hypot(R[..., i, i], R[..., i, j])


def matrix_to_euler(R, seq: str):
    """Both intrinsic Euler solutions of rotation matrices.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices (not validated here; see ``check_rotation``).
    seq : str
        Intrinsic right-handed axis sequence, e.g. ``"xyz"`` or ``"zxz"``.

    Returns
    -------
    sol1, sol2 : ndarray, shape (..., 3)
        Radians in ``(-pi, pi]``. ``sol1`` has ``|b| <= pi/2`` (Tait-Bryan) or
        ``b in [0, pi]`` (proper Euler); ``sol2`` is the other triple.
    lock : ndarray, shape (...)
        ``lock_distance`` of each row (0 at gimbal lock).
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected matrices of shape (..., 3, 3), got {R.shape}")
    shape = R.shape[:-2]
    a, b, c, lock = soa_to_euler(soa.from_array(R.reshape(-1, 3, 3)), seq)
    a2, b2, c2 = second_solution(a, b, c, seq)
    sol1 = wrap_pi(np.stack([a, b, c], axis=-1).reshape(shape + (3,)))  # atan2(-0.0, -1) is -pi
    sol2 = wrap_pi(np.stack([a2, b2, c2], axis=-1).reshape(shape + (3,)))
    return sol1, sol2, lock.reshape(shape)


def second_solution(a, b, c, seq: str):
    """The other triple of ``(a, b, c)`` (radians, each in ``(-pi, pi]``)."""
    i, _, k = parse_seq(seq)
    a2 = np.where(a > 0, a - np.pi, a + np.pi)
    c2 = np.where(c > 0, c - np.pi, c + np.pi)
    if i == k:
        b2 = np.where(b >= np.pi, b, -b)  # b in [0, pi]; -pi is written pi
    else:
        b2 = np.where(b >= 0, np.pi - b, -np.pi - b)
    return a2, b2, c2


def soa_to_euler(X, seq: str):
    """Solution 1 ``(a, b, c, lock)`` of a nested-list matrix (see :func:`matrix_to_euler`)."""
    i, j, k = parse_seq(seq)
    n = next(np.shape(v)[0] for row in X for v in row if not isinstance(v, float))
    X = [[np.broadcast_to(v, (n,)) if isinstance(v, float) else v for v in row] for row in X]
    if i == k:
        m = 3 - i - j
        e = parity(i, j, m)
        lock = np.sqrt(X[i][j] * X[i][j] + X[i][m] * X[i][m])  # entries <= 1: no overflow, unlike hypot's cost
        b = np.arctan2(lock, X[i][i])
        a = np.arctan2(X[j][i], -e * X[m][i])
        c = np.arctan2(X[i][j], e * X[i][m])
    else:
        e = parity(i, j, k)
        lock = np.sqrt(X[i][i] * X[i][i] + X[i][j] * X[i][j])
        if e > 0:
            b = np.arctan2(X[i][k], lock)
            a = np.arctan2(-X[j][k], X[k][k])
            c = np.arctan2(-X[i][j], X[i][i])
        else:
            b = np.arctan2(-X[i][k], lock)
            a = np.arctan2(X[j][k], X[k][k])
            c = np.arctan2(X[i][j], X[i][i])
    near = lock < REFINE_BELOW
    if near.any():
        R = soa.to_array([[v[near] for v in row] for row in X], int(near.sum()))
        a[near] = _first_from_residual(R, b[near], c[near], i, j, k)
        locked = lock < SPLIT_EPS
        if locked.any():
            sub = locked[near]
            a[locked], c[locked] = _split_locked(R[sub], b[locked], i, j, k)
    return a, b, c, lock


def _angle_about(M, i):
    """Angle of a rotation about axis ``i`` (as built by ``axis_rotation``)."""
    j1, k1 = (i + 1) % 3, (i + 2) % 3
    return np.arctan2(M[..., k1, j1], M[..., j1, j1])


def _first_from_residual(R, b, c, i, j, k):
    tail = np.matmul(axis_rotation(j, b), axis_rotation(k, c))
    return _angle_about(np.matmul(R, np.swapaxes(tail, -1, -2)), i)


def _split_locked(R, b, i, j, k):
    """At the lock only ``a + sigma*c`` is observable: give each turn half of it."""
    Rj = axis_rotation(j, b)
    total = _angle_about(np.matmul(R, np.swapaxes(Rj, -1, -2)), i)  # R = R_i(a + sigma c) R_j(b)
    sigma = np.sign(Rj[..., i, k])  # R_j(b) maps axis k onto sigma * axis i
    return total / 2, sigma * total / 2
