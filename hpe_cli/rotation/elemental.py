"""Elemental rotations, batched.

All functions take angles in radians (any shape ``S``) and return ``S + (3, 3)``
arrays. They are right-handed and active: ``rx(a) @ v`` turns ``v`` by ``a``
counter-clockwise about +x seen from +x. A left-handed turn is ``rx(-a)``.
"""

from __future__ import annotations

import numpy as np

AXES = "xyz"


def axis_rotation(axis: int, angle) -> np.ndarray:
    """Right-handed rotation by ``angle`` (radians) about axis 0, 1 or 2."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3))
    i, j, k = axis, (axis + 1) % 3, (axis + 2) % 3
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    return out


def rx(angle) -> np.ndarray:
    """Right-handed rotation about x, ``angle`` in radians."""
    return axis_rotation(0, angle)


def ry(angle) -> np.ndarray:
    """Right-handed rotation about y, ``angle`` in radians."""
    return axis_rotation(1, angle)


def rz(angle) -> np.ndarray:
    """Right-handed rotation about z, ``angle`` in radians."""
    return axis_rotation(2, angle)
