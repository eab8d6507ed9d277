"""The pair a protocol scores: ground truth and prediction as matrices and as the angles each side wrote."""

from __future__ import annotations

import numpy as np

from ..native import core_errors
from ..rotation import solutions
from ..rotation.systems import get_system
from . import peer_angles as pa_
from . import rotation_errors as re_

_DEG = 180.0 / np.pi


class PosePair:
    """Predicted (``P``) and true (``G``) canonical rotations with cached conversions.

    Parameters
    ----------
    P, G : nested list (3x3 of 1-D arrays) or ndarray (N, 3, 3)
        Canonical 300W-LP matrices (``A = Rx(p).T Ry(y).T Rz(r).T``).
    gt_system : RotationSystem
        The ground truth's own system (used by the core metrics).
    raw : dict, optional
        ``{"pred" | "gt": (system, angles (N, 3) degrees)}``: the angles as
        written in the input file, for sides that were given as angles. The
        raw-angle protocols compare these numbers as written.
    """

    def __init__(self, P, G, gt_system, raw=None, context=None):
        self.context = dict(context or {})
        self.P = re_.as_nested(P)
        self.G = re_.as_nested(G)
        self.gt_system = gt_system
        self.n = int(np.broadcast(*[x for row in self.G for x in row]).shape[0])
        self.raw = dict(raw or {})
        self._cache = {}

    def stored(self, system, side: str):
        """Nested stored matrix of ``side`` ('pred' or 'gt') in ``system``."""

        system = get_system(system)
        key = ("stored", system.name, side)
        if key not in self._cache:
            self._cache[key] = system.soa_from_canonical(self.P if side == "pred" else self.G)
        return self._cache[key]

    def angles(self, system, side: str):
        """``(primary, secondary)`` angles ``(N, 3)`` (pitch, yaw, roll; degrees) of ``side`` in ``system``."""

        system = get_system(system)
        key = ("angles", system.name, side)
        if key not in self._cache:
            p1 = self.primary(system, side)
            p2 = self._cache.pop(("second", system.name, side), None)
            if p2 is not None:  # kept as columns by primary(): stacked only when asked for
                p2 = np.stack(np.broadcast_arrays(*p2), -1)
            else:  # read as written: the other solution from the primary one
                p2 = np.stack(
                    solutions.second_degrees([p1[:, k] for k in range(3)], solutions.middle_role(system), False), -1
                )
            self._cache[key] = (p1, p2)
        return self._cache[key]

    def primary(self, system, side: str) -> np.ndarray:
        """The primary angles ``(N, 3)`` of ``side`` in ``system`` (degrees): rows written as angles in ``system``
        that are its primary triple are read as written (:func:`hpe_cli.rotation.solutions.primary_from_written`),
        the rest come from the matrix."""

        system = get_system(system)
        key = ("primary", system.name, side)
        if key in self._cache:
            return self._cache[key]
        raw = self.raw.get(side)
        fast = None
        if raw is not None and self.n:
            rsys = get_system(raw[0])
            if rsys.name == system.name or _same_angles(rsys, system):
                a = np.asarray(raw[1], dtype=np.float64)
                fast = solutions.primary_from_written(system, a)
        if fast is None or not fast.any():
            q1, q2, _, _ = system.soa_to_angles(self.stored(system, side))
            p1 = np.stack(np.broadcast_arrays(*q1), -1)
            self._cache[("second", system.name, side)] = q2
        else:
            p1 = np.array(a, dtype=np.float64)
            if not fast.all():
                slow = np.flatnonzero(~fast)  # few rows: gathered by index, not by nine scans of a mask
                X = self.stored(system, side)
                q1, _, _, _ = system.soa_to_angles([[np.broadcast_to(v, (self.n,))[slow] for v in row] for row in X])
                p1[slow] = np.stack(q1, -1)
        self._cache[key] = p1
        return p1

    def written(self, system, side: str):
        """Angles of ``side`` as a peer reading ``system`` labels sees them, and the re-expressed rows.

        When ``side`` was given as angles and those numbers mean the same
        rotation in ``system`` (same system, or one whose angles are the same
        numbers, e.g. 6drepnet and 300w_lp), they are returned as written: no
        re-extraction from the matrix, so a non-primary solution, a yaw past
        the range or a gimbal-lock label stays what the file says. Other rows
        (another system's angles, or matrices/vectors) take the primary
        solution of ``system`` from the matrix.

        Returns
        -------
        angles : ndarray (N, 3)
        changed : ndarray of bool (N,) or None
            Rows given as angles whose numbers were changed by the conversion;
            None when the side was not given as angles (all from the matrix).
        """

        system = get_system(system)
        key = ("written", system.name, side)
        if key in self._cache:
            return self._cache[key]
        raw = self.raw.get(side)
        if raw is None:
            out = (self.primary(system, side), None)
        else:
            rsys, a = get_system(raw[0]), np.asarray(raw[1], dtype=np.float64)
            if rsys.name == system.name or _same_angles(rsys, system):
                out = (a, np.zeros(self.n, dtype=bool))
            else:
                conv = self.primary(system, side)
                X = system.soa_to_canonical(system.soa_from_angles(a[:, 0], a[:, 1], a[:, 2]))
                C = self.P if side == "pred" else self.G
                same = np.ones(self.n, dtype=bool)
                for i in range(3):
                    for j in range(3):
                        same &= np.abs(np.asarray(X[i][j]) - C[i][j]) <= 1e-9
                out = (np.where(same[:, None], a, conv), ~same)
        self._cache[key] = out
        return out

    def core_errors(self) -> None:
        """The geodesic, column-angle and Frobenius errors at once where the compiled kernel gives their bits
        (:func:`hpe_cli.native.core_errors`; else each is computed when first asked for)."""
        if "geodesic" not in self._cache:
            got = core_errors(self.P, self.G)
            if got is not None:
                self._cache["geodesic"], self._cache["maev"], self._cache["frobenius"] = got

    def geodesic(self) -> np.ndarray:
        """:func:`hpe_cli.metrics.rotation_errors.geodesic_deg` of ``P`` and ``G`` (computed once)."""
        if "geodesic" not in self._cache:
            self._cache["geodesic"] = re_.geodesic_deg(self.P, self.G)
        return self._cache["geodesic"]

    def maev(self) -> np.ndarray:
        """:func:`hpe_cli.metrics.rotation_errors.maev_deg` of ``P`` and ``G`` (computed once)."""
        if "maev" not in self._cache:
            self._cache["maev"] = re_.maev_deg(self.P, self.G)
        return self._cache["maev"]

    def frobenius(self) -> np.ndarray:
        """:func:`hpe_cli.metrics.rotation_errors.frobenius` of ``P`` and ``G`` (computed once)."""
        if "frobenius" not in self._cache:
            self._cache["frobenius"] = re_.frobenius(self.P, self.G)
        return self._cache["frobenius"]

    def array(self, system, side: str) -> np.ndarray:
        """Stored matrices of ``side`` in ``system`` as ``(N, 3, 3)``."""
        return pa_.stack3(self.stored(system, side))


_SAME: dict = {}


def _same_angles(a, b) -> bool:
    """True when (pitch, yaw, roll) mean the same rotation in systems ``a`` and ``b`` for EVERY triple.

    Checked once per pair of systems on 2,000 triples spread over the whole
    [-180, 180]^3 cube (other solutions, past-range yaws, gimbal lock
    included): e.g. 300w_lp and 6drepnet angles are the same numbers.
    """
    key = (a.name, b.name)
    if key not in _SAME:
        rng = np.random.default_rng(0)
        t = np.concatenate(
            [
                rng.uniform(-180, 180, (1900, 3)),
                np.c_[rng.uniform(-180, 180, 100), np.repeat([90.0, -90.0], 50), rng.uniform(-180, 180, 100)],
            ]
        )
        Xa = a.soa_to_canonical(a.soa_from_angles(t[:, 0], t[:, 1], t[:, 2]))
        Xb = b.soa_to_canonical(b.soa_from_angles(t[:, 0], t[:, 1], t[:, 2]))
        _SAME[key] = all(
            np.allclose(np.broadcast_to(Xa[i][j], (len(t),)), np.broadcast_to(Xb[i][j], (len(t),)), atol=1e-12, rtol=0)
            for i in range(3)
            for j in range(3)
        )
    return _SAME[key]
