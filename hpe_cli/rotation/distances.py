"""Distances between rotations (SPEC §9). Compare matrices, never angles."""
from __future__ import annotations

import numpy as np


def frobenius(R1, R2) -> np.ndarray:
    """``||R1 - R2||_F`` per row; 0 for equal rotations, at most ``2*sqrt(2)``."""
    d = np.asarray(R1, dtype=np.float64) - np.asarray(R2, dtype=np.float64)
    return np.sqrt(np.einsum("...ij,...ij->...", d, d))


def geodesic_deg(R1, R2) -> np.ndarray:
    """Angle of ``R1.T @ R2`` in degrees, in [0, 180].

    Uses ``2 * atan2(||R1 - R2||_F, ||R1 + R2||_F)``, which equals
    ``acos((trace(R1.T R2) - 1) / 2)`` but stays accurate near 0 and 180 degrees.
    """
    R1 = np.asarray(R1, dtype=np.float64)
    R2 = np.asarray(R2, dtype=np.float64)
    dm, dp = R1 - R2, R1 + R2
    num = np.sqrt(np.einsum("...ij,...ij->...", dm, dm))
    den = np.sqrt(np.einsum("...ij,...ij->...", dp, dp))
    return np.rad2deg(2.0 * np.arctan2(num, den))


def angle_diff_deg(a, b) -> np.ndarray:
    """Wrapped angle difference ``min(|d|, 360 - |d|)`` in degrees."""
    d = np.abs(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)) % 360.0
    return np.minimum(d, 360.0 - d)
