"""Distances between rotations (SPEC §9). Compare matrices, never angles."""

from __future__ import annotations

import numpy as np


def frobenius(R1, R2) -> np.ndarray:
    """``||R1 - R2||_F`` per row; 0 for equal rotations, at most ``2*sqrt(2)``."""
    d = np.asarray(R1, dtype=np.float64) - np.asarray(R2, dtype=np.float64)
    return np.sqrt(np.einsum("...ij,...ij->...", d, d))


def geodesic_deg(R1, R2) -> np.ndarray:
    """Angle of ``R1.T @ R2`` in degrees, in [0, 180].

    Computed as ``atan2(sin, cos)`` of ``M = R1.T @ R2`` (``sin`` from the
    skew part, ``cos = (trace(M) - 1) / 2``), which equals the usual clamped
    ``acos`` but stays accurate near 0 and near 180 degrees.
    """
    M = np.matmul(np.swapaxes(np.asarray(R1, dtype=np.float64), -1, -2), np.asarray(R2, dtype=np.float64))
    sx = M[..., 2, 1] - M[..., 1, 2]
    sy = M[..., 0, 2] - M[..., 2, 0]
    sz = M[..., 1, 0] - M[..., 0, 1]
    sin = 0.5 * np.sqrt(sx * sx + sy * sy + sz * sz)
    cos = 0.5 * (M[..., 0, 0] + M[..., 1, 1] + M[..., 2, 2] - 1.0)
    return np.rad2deg(np.arctan2(sin, cos))


def angle_diff_deg(a, b) -> np.ndarray:
    """Wrapped angle difference ``min(|d|, 360 - |d|)`` in degrees."""
    d = np.abs(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)) % 360.0
    return np.minimum(d, 360.0 - d)
