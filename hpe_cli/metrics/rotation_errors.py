"""Errors between predicted and true rotations, batched (pure numpy).

Rotations enter either as ``(N, 3, 3)`` arrays or as 3x3 nested lists of 1-D
arrays (the structure-of-arrays form of :mod:`hpe_cli.rotation.soa`); both
sides must be in the same frame (``hpe`` uses the canonical 300W-LP frame).
Every function works on whole columns: no Python loop over rows.

Identities used (and tested):

* ``geodesic``: the angle of ``P @ G.T``; equal to the angle of ``G.T @ P``.
* ``frobenius``: ``||I - P @ G.T||_F = ||G - P||_F = 2*sqrt(2)*sin(theta/2)``.
* ``maev``: the angle between column ``j`` of ``P`` and of ``G`` (the head's
  left, up/down and front axes in camera coordinates): TriNet's vector errors
  (chuzcjoe/TriNet ``computeMAE.py``, ``W300_Get_MAE_NPY``: ``acos(clip(gt_v . pred_v))``
  for the left, bottom and front column vectors) and 6DRepNet360's "VMAE"
  Vec1..Vec3 (``sixdrepnet360/test.py``).
"""

from __future__ import annotations

import numpy as np

from ..native import best_of_two as native_best_of_two
from ..rotation.soa import frobenius as soa_frobenius

_DEG = 180.0 / np.pi

#: names of the three axes (columns of the canonical matrix) as the report spells them
AXES = ("left", "down", "front")


def as_nested(R):
    """A ``(N, 3, 3)`` array (or a nested list already) as a 3x3 nested list of 1-D arrays."""
    if isinstance(R, (list, tuple)):
        return R
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected matrices of shape (N, 3, 3), got {R.shape}")
    R = R.reshape(-1, 3, 3)
    return [[R[:, i, j] for j in range(3)] for i in range(3)]


def _trace_and_skew(P, G):
    """``trace(P G^T)`` and the norm of the skew part's axis vector (twice ``sin``)."""
    P, G = as_nested(P), as_nested(G)

    def m(k, l):  # (P G^T)[k, l]
        return P[k][0] * G[l][0] + P[k][1] * G[l][1] + P[k][2] * G[l][2]

    tr = m(0, 0) + m(1, 1) + m(2, 2)
    sx = m(2, 1) - m(1, 2)
    sy = m(0, 2) - m(2, 0)
    sz = m(1, 0) - m(0, 1)
    return tr, np.sqrt(sx * sx + sy * sy + sz * sz)


def geodesic_deg(P, G) -> np.ndarray:
    """Angle of ``P @ G.T`` in degrees, in [0, 180].

    ``atan2(sin, cos)`` with ``sin`` from the skew part and ``cos = (trace - 1) / 2``:
    the usual clamped ``acos`` but accurate near 0 and 180 degrees.

    Parameters
    ----------
    P, G : ndarray (N, 3, 3) or nested list
        Rotations in one frame.

    Returns
    -------
    ndarray (N,)
    """
    tr, two_sin = _trace_and_skew(P, G)
    return np.arctan2(0.5 * two_sin, 0.5 * (tr - 1.0)) * _DEG


def frobenius(P, G) -> np.ndarray:
    """``||I - P @ G.T||_F`` per row (DAD-3DHeads' pose error), in [0, 2*sqrt(2)].

    Computed as ``||P - G||_F``, which is the same number (multiply by the
    orthogonal ``G``) without the cancellation of ``I - P G^T`` for small errors.
    """

    return soa_frobenius(as_nested(P), as_nested(G))


def maev_deg(P, G) -> np.ndarray:
    """Angle in degrees between corresponding columns of ``P`` and ``G``.

    Returns
    -------
    ndarray (N, 3)
        One column per axis, in the order of :data:`AXES` (the canonical
        matrix's x, y, z columns: the head's left, up/down and front axes; the
        angle between two axes does not depend on the sign chosen for them).
    """
    P, G = as_nested(P), as_nested(G)
    n = int(np.broadcast(*[x for row in P for x in row], *[x for row in G for x in row]).shape[0])
    out = np.empty((n, 3))
    for j in range(3):  # in place, in the order of ``p0 g0 + p1 g1 + p2 g2`` and ``p1 g2 - p2 g1``...
        p = [np.broadcast_to(P[i][j], (n,)) for i in range(3)]
        g = [np.broadcast_to(G[i][j], (n,)) for i in range(3)]
        t = np.empty(n)
        dot = p[0] * g[0]
        dot += np.multiply(p[1], g[1], out=t)
        dot += np.multiply(p[2], g[2], out=t)
        norm = None
        for a, b in ((1, 2), (2, 0), (0, 1)):  # the cross product's x, y, z
            c = p[a] * g[b]
            c -= np.multiply(p[b], g[a], out=t)
            c *= c
            if norm is None:
                norm = c
            else:
                norm += c
        np.sqrt(norm, out=norm)
        np.arctan2(norm, dot, out=out[:, j])
    out *= _DEG
    return out


def wrap_abs_deg(d) -> np.ndarray:
    """``min(e, 360 - e)`` with ``e = |d| mod 360``: an angle difference wrapped into [0, 180]."""
    e = np.abs(np.asarray(d, dtype=np.float64))
    if e.size and not (e.max() < 360.0):  # differences of angles in (-180, 180] never need the (slow) fmod
        e = e % 360.0
    return np.minimum(e, 360.0 - e)


def abs_error(pred, gt) -> np.ndarray:
    """Plain ``|pred - gt|`` per angle (no wrap), degrees."""
    return np.abs(np.asarray(pred, dtype=np.float64) - np.asarray(gt, dtype=np.float64))


def wrapped_error(pred, gt) -> np.ndarray:
    """Per-angle ``|pred - gt|`` wrapped into [0, 180] (:func:`wrap_abs_deg`)."""
    return wrap_abs_deg(np.asarray(pred, dtype=np.float64) - np.asarray(gt, dtype=np.float64))


def best_of_two_error(pred1, pred2, gt) -> tuple[np.ndarray, np.ndarray]:
    """opal23's MAE: the prediction's better Euler solution, then each error wrapped.

    Follows ``compute_mae`` in pcr-upm/opal23_headpose ``test/evaluator.py``:
    the raw errors ``|gt - pred1|`` and ``|gt - pred2|`` are compared by their
    mean over the three angles (unwrapped), the smaller row is kept, and each
    kept error ``e`` becomes ``min(e, 360 - e)``.

    Parameters
    ----------
    pred1, pred2 : ndarray (N, 3)
        The prediction's two Euler solutions (same system as ``gt``), degrees.
    gt : ndarray (N, 3)

    Returns
    -------
    errors : ndarray (N, 3)
        In [0, 180].
    second : ndarray of bool (N,)
        Rows where the second solution was used.
    """
    p1, p2, g = (np.asarray(x, dtype=np.float64) for x in (pred1, pred2, gt))
    e1 = [np.abs(p1[..., k] - g[..., k]) for k in range(3)]
    e2 = [np.abs(p2[..., k] - g[..., k]) for k in range(3)]
    second = ((e2[0] + e2[1]) + e2[2]) / 3 < ((e1[0] + e1[1]) + e1[2]) / 3  # the row means, in mean's order
    out = np.empty(np.broadcast(p1, p2, g).shape)
    for k in range(3):
        e = np.where(second, e2[k], e1[k])
        np.minimum(e, 360.0 - e, out=out[..., k])
    return out, second


def best_and_wrapped(pred1, pred2, gt) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(best_of_two_error(pred1, pred2, gt)[0], its second-solution mask, wrapped_error(pred1, gt))`` in one
    compiled pass where :func:`hpe_cli.native.best_of_two` is built (the same numbers)."""
    got = native_best_of_two(pred1, pred2, gt, True)
    if got is not None:
        return got
    best, second = best_of_two_error(pred1, pred2, gt)
    return best, second, wrapped_error(pred1, gt)


def rotvec_deg(R) -> np.ndarray:
    """Rotation vectors (axis times angle, degrees) of rotations, batched; the log map ``cv2.Rodrigues`` computes.

    Rows with ``cos(theta) >= 0`` take the axis from the skew part
    (``(R - R.T) / 2 = sin(theta) [a]_x``); rows past 90 degrees from the
    symmetric part (``(R + R.T) / 2 - cos(theta) I = (1 - cos(theta)) a a.T``),
    which stays accurate up to 180 degrees, with the sign of ``a`` taken
    from the skew part.

    Parameters
    ----------
    R : ndarray (N, 3, 3) or nested list

    Returns
    -------
    ndarray (N, 3)
        Angle in [0, 180] degrees times the unit axis.
    """
    R = as_nested(R)
    sx = 0.5 * (R[2][1] - R[1][2])
    sy = 0.5 * (R[0][2] - R[2][0])
    sz = 0.5 * (R[1][0] - R[0][1])
    cos = 0.5 * (R[0][0] + R[1][1] + R[2][2] - 1.0)
    sin = np.sqrt(sx * sx + sy * sy + sz * sz)
    theta = np.arctan2(sin, cos)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(sin > 1e-300, theta / sin, 1.0)
    out = np.stack(np.broadcast_arrays(sx * k, sy * k, sz * k), -1)
    far = np.flatnonzero(cos < 0.0)
    if far.size:
        c = cos[far]
        Rf = [[np.broadcast_to(R[i][j], cos.shape)[far] for j in range(3)] for i in range(3)]
        d0, d1, d2 = Rf[0][0] - c, Rf[1][1] - c, Rf[2][2] - c  # (1 - cos) a_i^2
        o01 = 0.5 * (Rf[0][1] + Rf[1][0])  # (1 - cos) a_i a_j
        o02 = 0.5 * (Rf[0][2] + Rf[2][0])
        o12 = 0.5 * (Rf[1][2] + Rf[2][1])
        kk = np.argmax(np.stack([d0, d1, d2]), axis=0)  # the largest |a_k|: divide by it
        col = [np.choose(kk, [d0, o01, o02]), np.choose(kk, [o01, d1, o12]), np.choose(kk, [o02, o12, d2])]
        scale = 1.0 / np.sqrt(np.maximum(np.choose(kk, [d0, d1, d2]), 1e-300) * (1.0 - c))
        dot = col[0] * sx[far] + col[1] * sy[far] + col[2] * sz[far]
        f = np.where(dot < 0, -scale, scale) * theta[far]
        out[far] = np.stack([col[0] * f, col[1] * f, col[2] * f], -1)
    return out * _DEG
