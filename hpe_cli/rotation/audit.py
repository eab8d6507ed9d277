"""Per-row checks of head-pose labels (pure numpy, vectorised over rows).

Every check answers one yes/no question per row. The names are the keys of
``hpe audit``'s JSON report and the boolean columns of its ``-o`` table:

``non_finite``
    A label value is missing, non-numeric, NaN or infinite. Such rows get no
    other check (except ``duplicates``).
``not_rotation``
    Matrix input only: the nine finite entries are not a proper rotation
    (``||R R^T - I||_F`` or ``|det R - 1|`` above ``ROTATION_TOL``). Disjoint
    from ``non_finite``; such rows get no angle checks.
``gimbal_lock``
    Numerically locked: the system's ``lock_distance`` (``|cos b|`` of the
    middle turn ``b``, or ``|sin b|`` for proper Euler systems) is below
    ``system.gimbal_tol`` (1e-4 by default, 0.0057 deg). Only ``p + r`` or
    ``p - r`` can be recovered from such a label.
``near_gimbal``
    The middle turn is within ``near_tol_deg`` (1 deg by default) of its lock,
    i.e. ``lock_distance < sin(near_tol_deg)``, where splitting the other two
    angles amplifies label noise by ``1 / lock_distance``. **It includes the
    gimbal-locked rows**; ``near_gimbal & ~gimbal_lock`` are the rows close to,
    but not at, the lock. 300W-LP's HELEN_2375918801_1_14 label
    (-16.0909, -89.99858, -6.8545) is both.
``non_canonical``
    Angle input only: the triple is a valid rotation but not the system's
    primary solution (e.g. yaw 120 in ``300w_lp``, whose primary solution of
    that rotation has yaw 60 and pitch and roll moved by 180). The input is
    wrapped to (-180, 180] before the comparison, so 270 vs -90 is *not*
    non-canonical (it is ``out_of_range``). Not evaluated at gimbal lock, where
    the split of ``p +- r`` is a convention, not a solution.
``out_of_range``
    An angle outside (-180, 180] or outside the system's declared ``ranges``.
    For matrix input the primary angles are tested (e.g. a ``whenet`` rotation
    with no solution of |pitch| < 90 and |roll| < 90).
``duplicates``
    The row's key (its label values plus its id columns) equals the key of an
    earlier row; the first occurrence is not flagged. See
    :func:`duplicate_first`.
"""

from __future__ import annotations

import numpy as np

from ..native import kernels
from .check import ROTATION_TOL, rotation_mask, rotation_screen_columns
from .euler import parse_seq, wrap_180
from .solutions import middle_role
from .systems import RotationSystem, get_system

#: the check names, in report order
CHECKS = ("gimbal_lock", "near_gimbal", "non_canonical", "out_of_range", "non_finite", "not_rotation", "duplicates")

#: default ``near_gimbal`` tolerance, degrees from the lock
NEAR_GIMBAL_DEG = 1.0

#: two triples closer than this (degrees, per angle, wrapped) are the same solution;
#: the two solutions of one rotation differ by at least 2x the distance from the lock
CANONICAL_TOL_DEG = 1e-6


def _empty(n: int) -> dict:
    return {name: np.zeros(n, dtype=bool) for name in CHECKS}


def _range_mask(pyr, system: RotationSystem) -> np.ndarray:
    """True where an angle is outside (-180, 180] or the system's declared range."""
    outside = ((pyr <= -180.0) | (pyr > 180.0)).any(axis=-1)
    return outside | ~system.in_range(pyr)


def audit_angles(
    pyr_deg, system, near_tol_deg: float = NEAR_GIMBAL_DEG, canonical_tol_deg: float = CANONICAL_TOL_DEG
) -> dict:
    """Check angle labels.

    Parameters
    ----------
    pyr_deg : array_like, shape (N, 3)
        ``(pitch, yaw, roll)`` in degrees, any real values (NaN allowed).
    system : str or RotationSystem
        The labels' rotation system.
    near_tol_deg : float, optional
        ``near_gimbal`` tolerance in degrees, >= 0.
    canonical_tol_deg : float, optional
        Largest per-angle difference (degrees) still counted as the primary solution.

    Returns
    -------
    dict
        ``name -> bool array (N,)`` for every name in :data:`CHECKS`
        (``not_rotation`` and ``duplicates`` are all False here), plus
        ``lock_distance`` (N,) float (NaN for non-finite rows).
    """
    system = get_system(system)
    pyr = np.asarray(pyr_deg, dtype=np.float64).reshape(-1, 3)
    n = len(pyr)
    out = _empty(n)
    finite = np.isfinite(pyr).all(axis=1)
    out["non_finite"] = ~finite
    lock_all = np.full(n, np.nan)
    ok = np.flatnonzero(finite)
    if ok.size:
        p = pyr[ok]
        primary, _, locked, lock = system.to_angles(system.from_angles(p))
        near = locked | (lock < np.sin(np.deg2rad(near_tol_deg)))
        d = np.abs(wrap_180(p) - primary)
        d = np.minimum(d, 360.0 - d).max(axis=1)
        out["gimbal_lock"][ok] = locked
        out["near_gimbal"][ok] = near
        out["non_canonical"][ok] = ~locked & (d > canonical_tol_deg)
        out["out_of_range"][ok] = _range_mask(p, system)
        lock_all[ok] = lock
    out["lock_distance"] = lock_all
    return out


def audit_matrices(R, system, near_tol_deg: float = NEAR_GIMBAL_DEG, rotation_tol: float = ROTATION_TOL) -> dict:
    """Check matrix labels (the system's stored matrices).

    Parameters
    ----------
    R : array_like, shape (N, 3, 3)
        Stored matrices (NaN allowed).
    system : str or RotationSystem
    near_tol_deg : float, optional
        ``near_gimbal`` tolerance in degrees, >= 0.
    rotation_tol : float, optional
        Tolerance of the rotation test (see :func:`~hpe_cli.rotation.rotation_mask`).

    Returns
    -------
    dict
        As :func:`audit_angles` (``non_canonical`` is all False: a matrix has
        no choice of solution), plus ``primary`` (N, 3): the primary angles
        in degrees, NaN where the row is not a finite rotation.
    """
    system = get_system(system)
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    n = len(R)
    out = _empty(n)
    finite = np.isfinite(R).all(axis=(1, 2))
    rot = rotation_mask(R, rotation_tol)
    out["non_finite"] = ~finite
    out["not_rotation"] = finite & ~rot
    lock_all = np.full(n, np.nan)
    prim_all = np.full((n, 3), np.nan)
    ok = np.flatnonzero(rot)
    if ok.size:
        primary, _, locked, lock = system.to_angles(R[ok])
        out["gimbal_lock"][ok] = locked
        out["near_gimbal"][ok] = locked | (lock < np.sin(np.deg2rad(near_tol_deg)))
        out["out_of_range"][ok] = _range_mask(primary, system)
        lock_all[ok] = lock
        prim_all[ok] = primary
    out["lock_distance"] = lock_all
    out["primary"] = prim_all
    return out


def duplicate_first(keys) -> np.ndarray:
    """Index of the first row with the same key, for every row.

    Parameters
    ----------
    keys : array_like, shape (N,) or (N, K)
        One key per row (e.g. 64-bit hashes, two per row to make collisions
        negligible). Rows are equal when all ``K`` values are equal.

    Returns
    -------
    ndarray of int64 (N,)
        ``first[i] == i`` for the first occurrence of a key, else the index
        of that first occurrence; ``first != arange(N)`` is the duplicates mask.
    """
    k = np.asarray(keys)
    if k.ndim == 1:
        k = k[:, None]
    n = k.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    # fast path: a stable sort on the first column groups equal keys whenever rows
    # that share the first value share the whole key (always, for hashes in practice)
    order = np.argsort(k[:, 0], kind="stable")
    ks = k[order]
    new = np.ones(n, dtype=bool)
    new[1:] = ks[1:, 0] != ks[:-1, 0]
    if k.shape[1] > 1 and (~new[1:] & (ks[1:, 1:] != ks[:-1, 1:]).any(axis=1)).any():
        order = np.lexsort(k.T[::-1])  # exact: sort on every column
        ks = k[order]
        new[1:] = (ks[1:] != ks[:-1]).any(axis=1)
    group_start = np.maximum.accumulate(np.where(new, np.arange(n), 0))
    first = np.empty(n, dtype=np.int64)
    first[order] = order[group_start]
    return first


def audit_columns(
    cols,
    system,
    mode: str,
    near_tol_deg: float = NEAR_GIMBAL_DEG,
    canonical_tol_deg: float = CANONICAL_TOL_DEG,
    rotation_tol: float = ROTATION_TOL,
    *,
    lock_distance: bool = True,
    primary: bool = True,
) -> dict:
    """The checks of :func:`audit_angles` / :func:`audit_matrices` on label columns (structure of arrays).

    Parameters
    ----------
    cols : list of ndarray (N,)
        ``[pitch, yaw, roll]`` in degrees (``mode="angles"``) or the nine
        row-major entries ``r00..r22`` of the stored matrix (``mode="matrix"``);
        NaN allowed.
    system : str or RotationSystem
    mode : {"angles", "matrix"}
    lock_distance : bool, optional
        Also return ``lock_distance``. With False, angle labels of a Tait-Bryan
        system are screened by :func:`angle_flags_screened` (the middle angle's distance from the lock
        instead of the matrix round trip, the same masks).
    primary : bool, optional
        Matrix labels: also return ``primary``. With False (and
        ``lock_distance=False``), a system whose declared ranges every primary
        solution meets (:func:`matrix_screen_applies`) is checked without the
        decomposition: its lock distance is taken from the matrix entries as the
        decomposition takes it, and no row is out of range.

    Returns
    -------
    dict
        The same masks as the array functions (identical results, without
        building ``(N, 3, 3)`` stacks), plus ``lock_distance`` (unless
        ``lock_distance=False``) and, for matrices, ``primary`` (N, 3).
    """

    system = get_system(system)
    cols = [np.asarray(c, dtype=np.float64) for c in cols]
    n = len(cols[0])
    out = _empty(n)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        if mode == "angles":
            finite = np.isfinite(cols[0]) & np.isfinite(cols[1]) & np.isfinite(cols[2])
            safe = cols if finite.all() else [np.where(finite, c, 0.0) for c in cols]
            if not lock_distance and screen_applies(system, canonical_tol_deg):
                return angle_flags_screened(safe, finite, system, near_tol_deg, canonical_tol_deg)
            p1, _, locked, lock = system.soa_to_angles(system.soa_from_angles(*safe))
            pyr = np.stack(safe, axis=-1)
            primary = np.stack(p1, axis=-1)
            d = np.abs(wrap_180(pyr) - primary)
            d = np.minimum(d, 360.0 - d).max(axis=1)
            out["non_finite"] = ~finite
            out["gimbal_lock"] = locked & finite
            out["near_gimbal"] = (locked | (lock < np.sin(np.deg2rad(near_tol_deg)))) & finite
            out["non_canonical"] = ~locked & (d > canonical_tol_deg) & finite
            out["out_of_range"] = _range_mask(pyr, system) & finite
            out["lock_distance"] = np.where(finite, lock, np.nan)
            return out
        fin_entries = np.ones(n, dtype=bool)
        for c in cols:
            fin_entries &= np.isfinite(c)
        _, ortho, proper = rotation_screen_columns(cols, rotation_tol)
        rot = fin_entries & ortho & proper
        X = [cols[0:3], cols[3:6], cols[6:9]]
        if not rot.all():
            X = [[np.where(rot, c, float(i == j)) for j, c in enumerate(row)] for i, row in enumerate(X)]
        out["non_finite"] = ~fin_entries
        out["not_rotation"] = fin_entries & ~rot
        if not lock_distance and not primary and matrix_screen_applies(system):
            lock = tait_bryan_lock(X, system)
            locked = lock < system.gimbal_tol
            out["gimbal_lock"] = locked & rot
            out["near_gimbal"] = (locked | (lock < np.sin(np.deg2rad(near_tol_deg)))) & rot
            return out  # out_of_range stays False: every primary solution is in the declared ranges
        p1, _, locked, lock = system.soa_to_angles(X)
        angles = np.stack(p1, axis=-1)
        out["gimbal_lock"] = locked & rot
        out["near_gimbal"] = (locked | (lock < np.sin(np.deg2rad(near_tol_deg)))) & rot
        out["out_of_range"] = _range_mask(angles, system) & rot
        out["lock_distance"] = np.where(rot, lock, np.nan)
        out["primary"] = np.where(rot[:, None], angles, np.nan)
        return out


#: a screened decision whose middle angle's distance from the lock (degrees) is closer than this to the
#: threshold's is recomputed through the matrix round trip: the thresholds are under 89.9 degrees from the
#: lock, where this margin is at least 3e-11 of lock distance, and the round trip's lock distance differs from
#: ``|cos b|`` by a few 1e-16
SCREEN_MARGIN_DEG = 1e-6


def _screen_bound(t: float) -> float:
    """The distance ``d`` (degrees) of the middle angle from the lock below which ``|cos b| = sin d < t``, for
    ``d`` in [0, 90]: ``asin(t)`` (+inf above 1, never reached below 0)."""
    return float(np.degrees(np.arcsin(t))) if -1.0 <= t <= 1.0 else (np.inf if t > 1.0 else -1.0)


def screen_applies(system, canonical_tol_deg: float = CANONICAL_TOL_DEG) -> bool:
    """True when :func:`angle_flags_screened` gives :func:`audit_columns`' masks for ``system``.

    Tait-Bryan systems with the default primary solution (middle turn in
    [-90, 90] degrees) and a ``canonical_tol_deg`` between 1e-9 and 1 degree
    (the round trip of a primary triple moves it by less than 1e-9 degrees away
    from the lock; the other solution is 180 degrees away).
    """
    seq = system.intrinsic_axes
    return system.selection == "tait_bryan" and seq[0] != seq[2] and 1e-9 <= canonical_tol_deg <= 1.0


def angle_flags_screened(cols, finite, system, near_tol_deg=NEAR_GIMBAL_DEG, canonical_tol_deg=CANONICAL_TOL_DEG):
    """:func:`audit_columns`' masks for angle columns of a Tait-Bryan system, without the matrix round trip.

    For intrinsic Tait-Bryan turns ``a, b, c`` the stored matrix's lock distance
    is ``|cos b| = sin d`` with ``d = ||b| - 90|`` degrees (for ``|b| <= 180``), and the primary solution is
    the triple itself (wrapped to (-180, 180]) when ``|b| <= 90``, else the other one (every angle 180 degrees
    away), so ``gimbal_lock``, ``near_gimbal`` and ``non_canonical`` follow from ``d`` alone, compared with
    the thresholds' own distances (:func:`_screen_bound`): no cosine. Rows whose ``d`` lies within
    :data:`SCREEN_MARGIN_DEG` of a threshold's, with an angle outside [-180, 180], or every row when a
    threshold is within 0.1 degree of 90, go through the round trip of :func:`audit_columns`, so the masks
    are the same bits.

    Parameters
    ----------
    cols : list of 3 ndarray (N,)
        ``[pitch, yaw, roll]`` in degrees, finite where ``finite``.
    finite : ndarray of bool (N,)
    system : RotationSystem
        A system :func:`screen_applies` accepts.
    near_tol_deg, canonical_tol_deg : float
        As for :func:`audit_columns`.

    Returns
    -------
    dict
        ``name -> bool array (N,)`` for every name in :data:`CHECKS`.
    """
    n = len(finite)
    out = _empty(n)
    mid = middle_role(system)
    d_lock, d_near = _screen_bound(system.gimbal_tol), _screen_bound(float(np.sin(np.deg2rad(near_tol_deg))))
    k = kernels()
    if k is not None:  # the same masks in one C loop (csrc/kernels/screen.c); the numpy twin below
        ranges = [system.ranges.get(role, (-180.0, 180.0)) for role in ("pitch", "yaw", "roll")]
        unsure = np.empty(n, dtype=bool)
        out["non_finite"] = ~finite
        k.angle_screen(
            *(np.ascontiguousarray(c, dtype=np.float64) for c in cols),
            np.ascontiguousarray(finite, dtype=bool),
            mid,
            d_lock,
            d_near,
            SCREEN_MARGIN_DEG,
            d_lock > 89.9 or d_near > 89.9,
            tuple(float(lo) for lo, _ in ranges),
            tuple(float(hi) for _, hi in ranges),
            *(out[name] for name in ("gimbal_lock", "near_gimbal", "non_canonical", "out_of_range")),
            unsure,
        )
        return _exact_unsure(out, unsure, cols, system, near_tol_deg, canonical_tol_deg)
    a = np.abs(cols[mid])
    d = np.abs(a - 90.0)
    locked = d < d_lock
    inner = a <= 180.0
    for k in range(3):
        if k != mid:
            inner &= np.abs(cols[k]) <= 180.0
    unsure = ~inner
    for bound in (d_lock, d_near):
        if bound > 89.9:
            unsure[:] = True
        elif bound >= 0.0:
            unsure |= np.abs(d - bound) <= SCREEN_MARGIN_DEG
    unsure &= finite
    out["non_finite"] = ~finite
    out["gimbal_lock"] = locked & finite
    out["near_gimbal"] = (locked | (d < d_near)) & finite
    out["non_canonical"] = ~locked & (a > 90.0) & finite
    outside = ~inner
    for k, role in enumerate(("pitch", "yaw", "roll")):
        lo, hi = system.ranges.get(role, (-180.0, 180.0))  # (c <= -180) | (c < lo) | (c > hi), two comparisons
        outside |= ((cols[k] < lo) if lo > -180.0 else (cols[k] <= -180.0)) | (cols[k] > hi)
    out["out_of_range"] = outside & finite
    return _exact_unsure(out, unsure, cols, system, near_tol_deg, canonical_tol_deg)


def _exact_unsure(out, unsure, cols, system, near_tol_deg, canonical_tol_deg) -> dict:
    """``out`` with the screen's unsure rows decided by the round trip of :func:`audit_columns`."""
    idx = np.flatnonzero(unsure)
    if idx.size:
        exact = audit_columns([c[idx] for c in cols], system, "angles", near_tol_deg, canonical_tol_deg)
        for name in ("gimbal_lock", "near_gimbal", "non_canonical", "out_of_range"):
            out[name][idx] = exact[name]
    return out


def matrix_screen_applies(system) -> bool:
    """True when every primary solution of ``system`` is inside its declared ranges (and (-180, 180]).

    Tait-Bryan systems with the default primary solution: the middle angle is in
    [-90, 90] and the others in (-180, 180], so ranges that hold at least that
    (as ``300w_lp``'s yaw (-90, 90) and ``scipy_zyx``'s pitch) never flag a matrix.
    """
    seq = system.intrinsic_axes
    if system.selection != "tait_bryan" or seq[0] == seq[2]:
        return False
    middle = ("pitch", "yaw", "roll")[middle_role(system)]
    for role in ("pitch", "yaw", "roll"):
        lo, hi = system.ranges.get(role, (-180.0, 180.0))
        need = 90.0 if role == middle else 180.0
        if lo > -need or hi < need:
            return False
    return True


def tait_bryan_lock(X, system) -> np.ndarray:
    """The lock distance of stored matrices ``X`` (nested list) as :meth:`RotationSystem.soa_to_angles` computes
    it (the same arithmetic, so the same bits): ``sqrt(X[i][i]^2 + X[i][j]^2)`` of the system's axes."""
    if system.angle_frame == "canonical":
        X = system.soa_to_canonical(X)
    i, j, _ = parse_seq(system.intrinsic_axes)
    n = next(np.shape(v)[0] for row in X for v in row if not isinstance(v, float))
    a, b = (np.broadcast_to(v, (n,)) if isinstance(v, float) else v for v in (X[i][i], X[i][j]))
    return np.sqrt(a * a + b * b)
