"""Conversion between rotation systems through the canonical 300W-LP matrix."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import soa
from .systems import RotationSystem, get_system


@dataclass
class Conversion:
    """Labels of N rotations in one system.

    Attributes
    ----------
    primary, secondary : ndarray (N, 3)
        ``(pitch, yaw, roll)`` in degrees, both in ``(-180, 180]``.
    matrix : ndarray (N, 3, 3)
        The system's stored matrix.
    gimbal_lock : ndarray of bool (N,)
    roundtrip_err : ndarray (N,)
        Frobenius distance between the input rotation and the one rebuilt from
        ``primary`` (a few 1e-16 normally; up to ``gimbal_tol`` near the lock).
    canonical : ndarray (N, 3, 3)
        The canonical 300W-LP matrix ``A``.
    """

    primary: np.ndarray
    secondary: np.ndarray
    matrix: np.ndarray
    gimbal_lock: np.ndarray
    roundtrip_err: np.ndarray
    canonical: np.ndarray


def canonical_to_labels(A, target) -> Conversion:
    """Express canonical matrices ``A`` (N, 3, 3) in ``target`` (name, path or system)."""
    target = get_system(target)
    A = np.asarray(A, dtype=np.float64)
    n = A.shape[0]
    cols = soa_labels(soa.from_array(A), target, n)
    return Conversion(
        np.stack(cols["primary"], -1),
        np.stack(cols["secondary"], -1),
        soa.to_array(cols["matrix"], n),
        cols["gimbal_lock"],
        cols["roundtrip_err"],
        A,
    )


def soa_labels(A, target: RotationSystem, n: int, empty=np.empty) -> dict:
    """Labels of a nested-list canonical matrix ``A``: the columns behind :class:`Conversion`.

    Parameters
    ----------
    A : nested list (3x3) of 1-D float64 arrays of length ``n`` (or floats)
        Canonical 300W-LP matrices (:mod:`hpe_cli.rotation.soa`).
    target : RotationSystem
    n : int
        Rows, >= 0.
    empty : callable, optional
        ``empty(n)`` returns a writable float64 array of length ``n``: where the float output columns are
        allocated (a caller may hand out memory that outlives this call in its own pool).

    Returns
    -------
    dict
        ``primary``/``secondary`` (lists of 3 arrays, degrees), ``matrix`` (nested list, target's stored
        matrix), ``gimbal_lock`` and ``roundtrip_err`` (1-D arrays).

    Notes
    -----
    Computed :data:`~hpe_cli.rotation.soa.BLOCK` rows at a time; every row's numbers are those of the whole-column computation
    (element-wise operations in the same order; tested bit for bit).
    """
    R = target.soa_from_canonical(A)
    p1, p2 = [empty(n) for _ in range(3)], [empty(n) for _ in range(3)]
    locked, err = np.empty(n, dtype=bool), empty(n)
    for lo, hi in soa.blocks(n):
        q1, q2, lk, _ = target.soa_to_angles(soa.rows(R, lo, hi))
        rebuilt = target.soa_to_canonical(target.soa_from_angles(*q1))
        err[lo:hi] = soa.frobenius(soa.rows(A, lo, hi), rebuilt)
        for out, block in zip(p1 + p2, q1 + q2):
            out[lo:hi] = block
        locked[lo:hi] = lk
    return {"primary": p1, "secondary": p2, "matrix": R, "gimbal_lock": locked, "roundtrip_err": err}


def convert_matrices(R, source, target) -> Conversion:
    """Convert stored matrices of ``source`` into labels of ``target``."""
    return canonical_to_labels(get_system(source).to_canonical(R), target)


def convert_angles(pyr_deg, source, target) -> Conversion:
    """Convert ``(pitch, yaw, roll)`` degrees of ``source`` into labels of ``target``."""
    source: RotationSystem = get_system(source)
    return canonical_to_labels(source.to_canonical(source.from_angles(pyr_deg)), target)
