"""The two Euler solutions of a system's angles in degrees, and the primary one read straight off written angles.

A rotation away from gimbal lock has exactly two angle triples in a system:
the primary (``|b| <= 90`` for the middle Tait-Bryan turn, ``b in [0, 180]``
for a proper Euler one) and the other (:func:`second_degrees`). Angles that a
file already writes as the primary triple need no trip through the matrix:
:func:`primary_from_written` returns them as they are (the trip would give the
same numbers to ~1e-13 degrees) and names the rows that still need it (outside
(-180, 180], a middle turn past the primary range or within 3 degrees of the
lock, proper Euler systems, WHENet's selection).
"""

from __future__ import annotations

import numpy as np

from .. import native as _native

#: rows whose middle Tait-Bryan turn is within this many degrees of 90 go through the matrix
#: (their lock distance cos(b) is then below euler.REFINE_BELOW = 0.05, the refined branch)
LOCK_MARGIN_DEG = 3.0


def lift_low(d) -> None:
    """``d[d <= -180] += 360`` in place (degrees to (-180, ...]); the mask is built only when some row needs it."""
    low = d <= -180.0
    if low.any():
        d[low] += 360.0


def second_degrees(p1, middle: int, proper: bool) -> list:
    """The other solution of primary angles ``p1`` ([pitch, yaw, roll] arrays, degrees in (-180, 180]).

    ``middle`` is the role index (0 pitch, 1 yaw, 2 roll) of the middle turn.
    The first and last turns move by 180 degrees; the middle Tait-Bryan turn
    goes to ``180 - b`` (proper Euler: ``-b``). Every angle stays in (-180, 180].
    """
    got = _native.second_solution(p1, middle, proper)  # one C loop where built (the same bits)
    if got is not None:
        return list(got)
    p2 = []
    for role, d in enumerate(p1):
        # ``d2 - where(mask, 360, 0)`` is ``d2[mask] -= 360`` bit for bit (``x - 0.0`` is ``x``, -0.0 and NaN
        # included) without the gather and scatter of a boolean index
        if role != middle:
            d2 = d + 180.0
            np.subtract(d2, np.where(d > 0, 360.0, 0.0), out=d2)
        elif proper:
            d2 = -d
        else:
            d2 = 180.0 - d
            np.subtract(d2, np.where(d < 0, 360.0, 0.0), out=d2)
        lift_low(d2)  # tiny |d| rounds d - 180 to exactly -180
        p2.append(d2)
    return p2


def whenet_select(p1, p2):
    """WHENet's selection: the solution with ``|pitch| < 90`` and ``|roll| < 90`` when only the second has them."""
    ok1 = (np.abs(p1[0]) < 90) & (np.abs(p1[2]) < 90)
    ok2 = (np.abs(p2[0]) < 90) & (np.abs(p2[2]) < 90)
    swap = ~ok1 & ok2
    if swap.any():
        return [np.where(swap, y, x) for x, y in zip(p1, p2)], [np.where(swap, x, y) for x, y in zip(p1, p2)]
    return p1, p2


def primary_from_written(system, angles) -> np.ndarray:
    """Rows whose written angles ARE the system's primary solution, read without the matrix.

    Parameters
    ----------
    system : RotationSystem
        The system the angles are written in.
    angles : ndarray (N, 3)
        Pitch, yaw, roll in degrees, as written.

    Returns
    -------
    ndarray of bool (N,)
        True where every angle is in (-180, 180] and the middle turn is a
        Tait-Bryan one with ``|b| < 90 - LOCK_MARGIN_DEG``: there the primary
        solution extracted from the matrix equals the written triple. All False
        for proper Euler systems and WHENet's selection.
    """
    a = np.asarray(angles, dtype=np.float64)
    n = a.shape[0]
    if system.selection != "tait_bryan" or system.intrinsic_axes[0] == system.intrinsic_axes[2]:
        return np.zeros(n, dtype=bool)
    ok = np.abs(a[:, middle_role(system)]) < 90.0 - LOCK_MARGIN_DEG
    for k in range(3):
        ok &= (a[:, k] > -180.0) & (a[:, k] <= 180.0)
    return ok


def middle_role(system) -> int:
    """Role index (0 pitch, 1 yaw, 2 roll) of the system's middle turn."""
    return ("pitch", "yaw", "roll").index(system._intrinsic_turns()[1].angle)
