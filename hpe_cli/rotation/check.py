"""Validation of rotation matrices. Nothing here "fixes" its input."""

from __future__ import annotations

import numpy as np

from .soa import BLOCK, blocks

#: default tolerance on ||R R^T - I||_F and |det R - 1|: float32 storage gives ~1e-7
ROTATION_TOL = 1e-5


def rotation_error(R) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormality error ``||R R^T - I||_F`` and ``det(R)`` per row."""
    R = np.asarray(R, dtype=np.float64)
    g = np.matmul(R, np.swapaxes(R, -1, -2)) - np.eye(3)
    return np.sqrt(np.einsum("...ij,...ij->...", g, g)), np.linalg.det(R)


def _screen(R, tol):
    """``(finite, orthonormal, proper)`` masks; non-finite rows are screened as the identity."""
    R = np.asarray(R, dtype=np.float64)
    finite = np.isfinite(R).all(axis=(-1, -2))
    err, det = rotation_error(np.where(finite[..., None, None], R, np.eye(3)))
    return finite, err <= tol, np.abs(det - 1.0) <= tol


def rotation_mask(R, tol: float = ROTATION_TOL) -> np.ndarray:
    """True where ``R`` is finite, orthonormal within ``tol`` and has det +1."""
    finite, ortho, proper = _screen(R, tol)
    return finite & ortho & proper


def rotation_reasons(R, tol: float = ROTATION_TOL) -> np.ndarray:
    """Per-row reason strings: '' for a rotation, else why not (object array)."""
    finite, ortho, proper = _screen(R, tol)
    out = np.full(finite.shape, "", dtype=object)
    out[~ortho] = "not a rotation: not orthonormal"
    out[ortho & ~proper] = "not a rotation: determinant is not +1 (a reflection)"
    out[~finite] = "non-finite matrix entry"
    return out


def rotation_screen_columns(cols, tol: float = ROTATION_TOL):
    """Column-wise (structure-of-arrays) screen of row-major matrix entries.

    Parameters
    ----------
    cols : sequence of 9 ndarray (n,)
        ``r00, r01, ..., r22`` as contiguous float arrays.
    tol : float
        Tolerance on ``||R R^T - I||_F`` and ``|det R - 1|``.

    Returns
    -------
    finite, orthonormal, proper : ndarray of bool (n,)
        The same tests as :func:`rotation_mask`, without building ``(n, 3, 3)``
        arrays (about 10x faster), :data:`~hpe_cli.rotation.soa.BLOCK` rows at a time. Non-finite rows are
        False in all three.
    """
    cols = [np.asarray(x, dtype=np.float64) for x in cols]
    n = cols[0].shape[0] if cols[0].ndim == 1 else -1
    if n <= BLOCK or any(c.shape != (n,) for c in cols):
        return _screen_columns(cols, tol)
    out = [np.empty(n, dtype=bool) for _ in range(3)]
    for lo, hi in blocks(n):
        for o, v in zip(out, _screen_columns([c[lo:hi] for c in cols], tol)):
            o[lo:hi] = v
    return tuple(out)


def _screen_columns(cols, tol):
    a, b, c, d, e, f, g, h, i = cols
    with np.errstate(invalid="ignore", over="ignore"):
        # G = R R^T - I, symmetric: diagonal and the three upper entries
        g00 = a * a + b * b + c * c - 1.0
        g11 = d * d + e * e + f * f - 1.0
        g22 = g * g + h * h + i * i - 1.0
        g01 = a * d + b * e + c * f
        g02 = a * g + b * h + c * i
        g12 = d * g + e * h + f * i
        err2 = g00 * g00 + g11 * g11 + g22 * g22 + 2.0 * (g01 * g01 + g02 * g02 + g12 * g12)
        det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
        finite = np.isfinite(err2) & np.isfinite(det)
        ortho = err2 <= tol * tol
        proper = np.abs(det - 1.0) <= tol
    return finite, ortho & finite, proper & finite


def check_rotation(R, tol: float = ROTATION_TOL) -> np.ndarray:
    """Return ``R`` as float64 ``(..., 3, 3)`` or raise ``ValueError`` naming the first bad row."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected matrices of shape (..., 3, 3), got {R.shape}")
    reasons = rotation_reasons(R, tol).reshape(-1)
    bad = np.flatnonzero(reasons != "")
    if bad.size:
        raise ValueError(f"row {bad[0]}: {reasons[bad[0]]} ({bad.size} bad rows in all)")
    return R
