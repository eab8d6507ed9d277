"""Rotation systems: what a head-pose label means, as data (the :class:`RotationSystem` model).

A :class:`RotationSystem` relates its own matrix to the canonical 300W-LP
matrix ``A`` (SPEC §2) by

    R_active = B @ A @ B.T        R_stored = R_active  or  R_active.T

where ``B`` (``frame``) maps canonical coordinates to the system's coordinates
(``v_sys = B @ v_canonical``). Its angles build ``R_stored`` from three turns,
each about one of the system's axes, right- or left-handed, applied in an
intrinsic or extrinsic sequence.

Angles cross this API in *role order* ``(pitch, yaw, roll)`` and in degrees,
whatever the system's storage order or units; ``order`` and ``units`` only
describe how a dataset stores them on disk.

The frame ``B`` may be improper (det -1, e.g. image axes x right, y down, z
towards the viewer): ``B @ A @ B.T`` is still a proper rotation. A system may
also name a different head-model frame ``M`` (``model_frame``), giving
``R_active = B @ A @ M.T`` (DAD-3DHeads' benchmark matrix maps the FLAME model
frame into the OpenCV camera frame); ``det B * det M`` must be +1.

``storage_kind`` says what a dataset's file holds: ``angles`` (three turns),
``matrix`` (3x3, or the rotation block of a 4x4), ``rotvec`` (radians),
``quaternion`` (``quaternion_order`` wxyz or xyzw) or ``6d`` (two matrix
columns, ``sixd_columns``). Their file column names are ``value_columns``
(defaults per kind, renamed by a ``[columns]`` table). A system that stores no
angles and declares no turns reports the 300W-LP angles of the same rotation.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

import numpy as np

from .. import native as _native
from . import euler as _euler
from . import soa as _soa
from . import solutions as _solutions
from .check import rotation_reasons
from .system_text import CANONICAL_WORDS, format_number, format_value, toml_escape

ROLES = ("pitch", "yaw", "roll")
SELECTIONS = ("tait_bryan", "proper", "whenet")
STORAGE_KINDS = ("angles", "matrix", "rotvec", "quaternion", "6d")
MATRIX_LAYOUTS = ("3x3", "4x4")

#: default gimbal-lock tolerance on |cos b| (radians from the lock): 1e-4 rad is
#: 0.0057 deg. Closer than that, float32-stored labels (Pose_Para, most datasets)
#: split pitch from roll with errors above ~0.05 deg.
GIMBAL_TOL = 1e-4

_DEG = 180.0 / np.pi


#: the 300W-LP turns: the angles reported by systems that store no angles
CANONICAL_TURNS = None  # set after Turn is defined


def default_value_names(kind: str, layout: str = "3x3", quaternion_order: str = "wxyz") -> tuple:
    """Canonical names of the stored values of a storage kind (the keys of ``[columns]``)."""
    if kind == "angles":
        return ROLES
    if kind == "matrix":
        p = "m" if layout == "4x4" else "r"
        return tuple(f"{p}{i}{j}" for i in range(3) for j in range(3))
    if kind == "rotvec":
        return ("rx", "ry", "rz")
    if kind == "quaternion":
        return tuple("q" + c for c in quaternion_order)
    if kind == "6d":
        return tuple(f"sixd_{i}" for i in range(6))
    raise SystemError_(f"expected storage_kind in {STORAGE_KINDS}, got {kind!r}")


class SystemError_(ValueError):
    """An invalid or unknown rotation system."""


@dataclass(frozen=True)
class Turn:
    """One elemental turn: which angle, about which of the system's axes, which hand."""

    angle: str
    axis: str
    hand: str = "right"

    def sign(self) -> float:
        return 1.0 if self.hand == "right" else -1.0


CANONICAL_TURNS = (Turn("pitch", "x", "left"), Turn("yaw", "y", "left"), Turn("roll", "z", "left"))


@dataclass(frozen=True)
class RotationSystem:
    """A head-pose rotation system (frame, turns, sequence, storage, range, rule).

    Attributes
    ----------
    name : str
    description : str
    frame : tuple of 3 tuples
        ``B``: row ``n`` is the system's axis ``n`` written in canonical
        coordinates (canonical: x = subject's left, y = up, z = out of the face).
    turns : tuple of Turn
        The three turns in the order they are applied.
    sequence : {"intrinsic", "extrinsic"}
    storage : {"active", "transposed"}
        ``active`` maps head-model coordinates to camera-side coordinates.
    order : tuple of str
        Storage order of the angles in the dataset's own files.
    units : {"degrees", "radians"}
        Units of the dataset's own files.
    ranges : dict
        Declared range of each angle, degrees, ``{role: (lo, hi)}``.
    selection : {"tait_bryan", "proper", "whenet"}
        Which of the two solutions is primary. ``tait_bryan``: middle angle in
        [-90, 90]; ``proper``: middle angle in [0, 180]; ``whenet``: the solution
        with |pitch| < 90 and |roll| < 90 (WHENet's ``select_euler``), else the
        first one (such rows are flagged out of range).
    gimbal_tol : float
        Rows with ``lock_distance < gimbal_tol`` are flagged as gimbal-locked.
    storage_kind : {"angles", "matrix", "rotvec", "quaternion", "6d"}
        What the dataset's own files hold.
    matrix_layout : {"3x3", "4x4"}
        For ``matrix``: a 3x3 matrix or the rotation block of a 4x4 one.
    quaternion_order : {"wxyz", "xyzw"}
    sixd_columns : (int, int)
        For ``6d``: which two columns of the stored matrix, in file order.
    model_frame : tuple of 3 tuples or None
        ``M``, the head-model frame when it differs from ``frame``.
    columns : dict
        Canonical value name -> file column name (see :func:`default_value_names`).
    angle_frame : {"system", "canonical"}
        ``canonical``: the system has no turns of its own; its angles are the
        300W-LP angles of the same rotation.
    source, verified : str
        The code or document the definition follows, and how it was checked.
    examples : tuple of dict
        Worked examples (``angles`` or ``canonical_angles`` -> ``matrix``/``values``).
    """

    name: str
    description: str
    frame: tuple
    turns: tuple
    sequence: str = "intrinsic"
    storage: str = "active"
    order: tuple = ROLES
    units: str = "degrees"
    ranges: dict = field(default_factory=dict)
    selection: str = "tait_bryan"
    gimbal_tol: float = GIMBAL_TOL
    notes: str = ""
    storage_kind: str = "angles"
    matrix_layout: str = "3x3"
    quaternion_order: str = "wxyz"
    sixd_columns: tuple = (0, 1)
    model_frame: tuple | None = None
    columns: dict = field(default_factory=dict)
    angle_frame: str = "system"
    source: str = ""
    verified: str = ""
    examples: tuple = ()

    # ------------------------------------------------------------------ checks
    def __post_init__(self):
        for key, F in (("frame", self.frame), ("model_frame", self.model_frame)):
            if F is None:
                continue
            B = np.asarray(F, dtype=float)
            if B.shape != (3, 3) or not np.isfinite(B).all() or not np.allclose(B @ B.T, np.eye(3), atol=1e-9):
                raise SystemError_(
                    f"system {self.name!r}: {key}: expected an orthonormal 3x3 matrix (det +1 or -1), got {format_value(F)}"
                )
        if np.linalg.det(self.B) * np.linalg.det(self.M) < 0:
            raise SystemError_(
                f"system {self.name!r}: model_frame: expected det(frame) * det(model_frame) = +1 "
                f"(a proper rotation), got {np.linalg.det(self.B) * np.linalg.det(self.M):+.0f}"
            )
        if len(self.turns) != 3 or sorted(t.angle for t in self.turns) != sorted(ROLES):
            raise SystemError_(f"system {self.name!r}: expected three turns, one each for pitch, yaw, roll")
        for t in self.turns:
            if t.axis not in ("x", "y", "z") or t.hand not in ("right", "left"):
                raise SystemError_(f"system {self.name!r}: bad turn {t}: axis must be x/y/z, hand right/left")
        _euler.parse_seq(self.axes)
        for attr, allowed in (
            ("sequence", ("intrinsic", "extrinsic")),
            ("storage", ("active", "transposed")),
            ("units", ("degrees", "radians")),
            ("selection", SELECTIONS),
            ("storage_kind", STORAGE_KINDS),
            ("matrix_layout", MATRIX_LAYOUTS),
            ("quaternion_order", ("wxyz", "xyzw")),
            ("angle_frame", ("system", "canonical")),
        ):
            if getattr(self, attr) not in allowed:
                raise SystemError_(
                    f"system {self.name!r}: {attr}: expected one of {', '.join(allowed)}, got {getattr(self, attr)!r}"
                )
        if sorted(self.order) != sorted(ROLES):
            raise SystemError_(
                f"system {self.name!r}: order: expected a permutation of {', '.join(ROLES)}, got {list(self.order)}"
            )
        g = self.gimbal_tol
        if not isinstance(g, (int, float)) or not np.isfinite(g) or g < 0 or g >= 1:
            raise SystemError_(f"system {self.name!r}: gimbal_tol: expected a number in [0, 1), got {g!r}")
        for role, rng in self.ranges.items():
            if role not in ROLES:
                raise SystemError_(
                    f"system {self.name!r}: ranges.{role}: expected a key among {', '.join(ROLES)}, got {role!r}"
                )
            lo, hi = rng
            if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
                raise SystemError_(
                    f"system {self.name!r}: ranges.{role}: expected [low, high] with finite "
                    f"low < high (degrees), got [{lo!r}, {hi!r}]"
                )
        try:
            from .storage import check_sixd_pair

            check_sixd_pair(self.sixd_columns)
        except ValueError as exc:
            raise SystemError_(f"system {self.name!r}: sixd_columns: {exc}") from None
        names = self.value_names
        for key, col in self.columns.items():
            if key not in names:
                raise SystemError_(
                    f"system {self.name!r}: columns.{key}: expected a key among "
                    f"{', '.join(names)} (storage_kind {self.storage_kind}), got {key!r}"
                )
            if not isinstance(col, str) or not col:
                raise SystemError_(f"system {self.name!r}: columns.{key}: expected a column name, got {col!r}")
        vc = self.value_columns
        if len(set(vc)) != len(vc):
            raise SystemError_(f"system {self.name!r}: columns: expected distinct column names, got {list(vc)}")

    # ------------------------------------------------------------- derived bits
    @property
    def axes(self) -> str:
        """The axis letters in application order, e.g. ``"xyz"``."""
        return "".join(t.axis for t in self.turns)

    @property
    def intrinsic_axes(self) -> str:
        return self.axes if self.sequence == "intrinsic" else self.axes[::-1]

    def _intrinsic_turns(self):
        return self.turns if self.sequence == "intrinsic" else self.turns[::-1]

    @property
    def B(self) -> np.ndarray:
        return np.asarray(self.frame, dtype=np.float64)

    @property
    def M(self) -> np.ndarray:
        """The head-model frame (``frame`` unless ``model_frame`` is given)."""
        return self.B if self.model_frame is None else np.asarray(self.model_frame, dtype=np.float64)

    @property
    def proper_frame(self) -> bool:
        return bool(np.linalg.det(self.B) > 0)

    @property
    def value_names(self) -> tuple:
        """Canonical names of the stored values (keys of ``[columns]``)."""
        return default_value_names(self.storage_kind, self.matrix_layout, self.quaternion_order)

    @property
    def value_columns(self) -> list:
        """File column names of the stored values, in :attr:`value_names` order."""
        return [self.columns.get(k, k) for k in self.value_names]

    @property
    def value_units(self) -> str:
        """Units of angle value columns: the system's ``units`` when it names its own columns, else degrees."""
        return self.units if (self.storage_kind == "angles" and self.columns) else "degrees"

    # ---------------------------------------------------------- stored values
    def values_to_matrix(self, values):
        """Stored matrices ``(N, 3, 3)`` from stored values ``(N, k)`` (``value_names`` order).

        Returns ``(R, reasons)``; ``reasons`` is None when every row is usable,
        else an object array ('' for usable rows). Quaternions must have unit
        norm within 1e-3 (they are then normalised); 6-D vectors must not be
        degenerate; matrices must be rotations (:func:`~hpe_cli.rotation.check.rotation_reasons`).
        Angles are not handled here (see :meth:`from_angles`).
        """
        from . import storage as st  # lazy: start-up

        v = np.asarray(values, dtype=np.float64)
        n = v.shape[0]
        reasons = None

        def flag(mask, text):
            nonlocal reasons
            if mask.any():
                if reasons is None:
                    reasons = np.full(n, "", dtype=object)
                reasons[mask & (reasons == "")] = text

        kind = self.storage_kind
        if kind == "matrix":
            R = v.reshape(-1, 3, 3)
        elif kind == "rotvec":
            R = st.rotvec_to_matrix(v)
        elif kind == "quaternion":
            norm = np.linalg.norm(v, axis=-1)
            bad = ~(np.abs(norm - 1.0) <= 1e-3)
            flag(bad, "not a unit quaternion (norm differs from 1 by more than 1e-3)")
            R = (
                st.quaternion_to_matrix(np.where(bad[:, None], [1.0, 0, 0, 0], v), "wxyz")
                if self.quaternion_order == "wxyz"
                else st.quaternion_to_matrix(np.where(bad[:, None], [0, 0, 0, 1.0], v), "xyzw")
            )
        elif kind == "6d":
            R = st.sixd_to_matrix(v, self.sixd_columns)
            flag(~np.isfinite(R).all(axis=(1, 2)), "degenerate 6-D vector (zero or parallel columns)")
            R = np.where(np.isfinite(R), R, np.eye(3))
        else:
            raise SystemError_(f"system {self.name!r}: values_to_matrix: no stored values for storage_kind angles")
        if kind == "matrix":
            rr = rotation_reasons(R)
            flag(rr != "", "")
            if reasons is not None:
                reasons[rr != ""] = rr[rr != ""]
        return R, reasons

    def matrix_to_values(self, R) -> np.ndarray:
        """Stored values ``(N, k)`` (``value_names`` order) of stored matrices ``(N, 3, 3)``."""
        from . import storage as st  # lazy: start-up

        R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
        kind = self.storage_kind
        if kind == "matrix":
            return R.reshape(-1, 9)
        if kind == "rotvec":
            return st.matrix_to_rotvec(R)
        if kind == "quaternion":
            return st.matrix_to_quaternion(R, self.quaternion_order)
        if kind == "6d":
            return st.matrix_to_sixd(R, self.sixd_columns)
        raise SystemError_(f"system {self.name!r}: matrix_to_values: no stored values for storage_kind angles")

    # ----------------------------------------------------------------- kernels
    def from_angles(self, pyr_deg) -> np.ndarray:
        """Stored matrices ``(N, 3, 3)`` from angles ``(N, 3)`` in role order, degrees."""
        pyr = np.asarray(pyr_deg, dtype=np.float64)
        flat = pyr.reshape(-1, 3)
        X = self.soa_from_angles(flat[:, 0], flat[:, 1], flat[:, 2])
        return _soa.to_array(X, flat.shape[0]).reshape(pyr.shape[:-1] + (3, 3))

    def to_angles(self, R):
        """Both solutions of stored matrices, in role order and degrees.

        Returns
        -------
        primary, secondary : ndarray (N, 3)
            ``(pitch, yaw, roll)`` in degrees, each in ``(-180, 180]``;
            ``primary`` follows ``selection``.
        locked : ndarray of bool (N,)
            Within ``gimbal_tol`` of gimbal lock.
        lock : ndarray (N,)
            ``lock_distance`` (|cos| or |sin| of the middle turn).
        """
        R = np.asarray(R, dtype=np.float64)
        shape = R.shape[:-2]
        p1, p2, locked, lock = self.soa_to_angles(_soa.from_array(R.reshape(-1, 3, 3)))
        return (
            np.stack(p1, -1).reshape(shape + (3,)),
            np.stack(p2, -1).reshape(shape + (3,)),
            locked.reshape(shape),
            lock.reshape(shape),
        )

    def to_canonical(self, R_stored) -> np.ndarray:
        """Map stored matrices to the canonical 300W-LP matrix ``A``."""
        return self._map_array(R_stored, self.soa_to_canonical)

    def from_canonical(self, A) -> np.ndarray:
        """Map canonical matrices ``A`` to this system's stored matrices."""
        return self._map_array(A, self.soa_from_canonical)

    @staticmethod
    def _map_array(R, soa_map):
        R = np.asarray(R, dtype=np.float64)
        flat = R.reshape(-1, 3, 3)
        return _soa.to_array(soa_map(_soa.from_array(flat)), flat.shape[0]).reshape(R.shape)

    # nested-list (structure of arrays) forms of the same four maps, for hot paths
    @property
    def _identity_frame(self) -> bool:
        return np.array_equal(self.B, np.eye(3)) and np.array_equal(self.M, np.eye(3))

    def soa_from_angles(self, pitch, yaw, roll):
        """Stored matrix as a nested list, from 1-D angle arrays in degrees."""
        by_role = {"pitch": pitch, "yaw": yaw, "roll": roll}
        turns = self._intrinsic_turns()
        rad = [np.asarray(by_role[t.angle], dtype=np.float64) * (t.sign() * (np.pi / 180.0)) for t in turns]
        X = _euler.euler_to_soa(rad[0], rad[1], rad[2], self.intrinsic_axes)
        return self.soa_from_canonical(X) if self.angle_frame == "canonical" else X

    def soa_to_angles(self, X):
        """``(primary, secondary, locked, lock)`` with the angle triples as lists ``[pitch, yaw, roll]``.

        In one compiled loop where :func:`hpe_cli.native.system_angles` gives these numbers (the same bits; the
        rows within about 2.9 degrees of the lock, whose first angle is solved from the residual, are recomputed
        here)."""
        if self.angle_frame == "canonical":
            X = self.soa_to_canonical(X)
        got = self._compiled_angles(X)
        p1, p2, lock = got if got is not None else self._numpy_angles(X)
        if self.selection == "whenet":
            p1, p2 = _solutions.whenet_select(p1, p2)
        return p1, p2, lock < self.gimbal_tol, lock

    def _numpy_angles(self, X):
        """``(primary, secondary, lock)`` of :meth:`soa_to_angles` before the selection, in numpy."""
        seq = self.intrinsic_axes
        a, b, c, lock = _euler.soa_to_euler(X, seq)
        turns = self._intrinsic_turns()
        proper = seq[0] == seq[2]
        first = {}
        for t, v in zip(turns, (a, b, c)):
            d = v * (_DEG if t.hand == "right" else -_DEG)
            _solutions.lift_low(d)  # atan2(-0.0, -1) and left hands give -180; keep (-180, 180]
            first[t.angle] = d
        p1 = [first[role] for role in ROLES]
        return p1, _solutions.second_degrees(p1, _solutions.middle_role(self), proper), lock

    def _compiled_angles(self, X):
        """:meth:`_numpy_angles` by :func:`hpe_cli.native.system_angles`, its near-lock rows by :meth:`_numpy_angles`;
        None where the kernel is not used."""
        seq = self.intrinsic_axes
        i, j, k = _euler.parse_seq(seq)
        proper = i == k
        if proper:
            k = 3 - i - j
        turns = self._intrinsic_turns()
        spec = (i, j, k, proper, _euler.parity(i, j, k))
        scale = tuple(_DEG if t.hand == "right" else -_DEG for t in turns)
        roles = tuple(ROLES.index(t.angle) for t in turns)
        got = _native.system_angles(X, spec, scale, roles, _solutions.middle_role(self), _euler.REFINE_BELOW)
        if got is None:
            return None
        p1, p2, lock, near = got
        if near.any():  # few rows: the twin on them alone (element-wise, so the same bits as on every row)
            idx = np.flatnonzero(near)
            q1, q2, lk = self._numpy_angles([[np.broadcast_to(v, (len(lock),))[idx] for v in row] for row in X])
            for r in range(3):
                p1[r][idx], p2[r][idx] = q1[r], q2[r]
            lock[idx] = lk
        return list(p1), list(p2), lock

    def soa_to_canonical(self, X):
        """``A = B.T @ R_active @ M`` (``R_active`` is the stored matrix, transposed if stored so)."""
        if self.storage == "transposed":
            X = _soa.transpose(X)
        if self._identity_frame:
            return X
        return _soa.mul(_soa.mul(_soa.constant(self.B.T), X), _soa.constant(self.M))

    def soa_from_canonical(self, A):
        """``R_active = B @ A @ M.T``, then transposed if the system stores the inverse."""
        X = A
        if not self._identity_frame:
            X = _soa.mul(_soa.mul(_soa.constant(self.B), A), _soa.constant(self.M.T))
        return _soa.transpose(X) if self.storage == "transposed" else X

    def in_range(self, pyr_deg) -> np.ndarray:
        """Boolean mask: every angle inside the declared range (inclusive)."""
        pyr = np.asarray(pyr_deg, dtype=np.float64)
        ok = np.ones(pyr.shape[:-1], dtype=bool)
        for n, role in enumerate(ROLES):
            lo, hi = self.ranges.get(role, (-180.0, 180.0))
            ok &= (pyr[..., n] >= lo) & (pyr[..., n] <= hi)
        return ok

    # ------------------------------------------------------------ description
    def frame_words(self, frame=None) -> dict:
        """The system's x, y, z axes described in words."""
        frame = self.frame if frame is None else frame
        words = {}
        for n, axis in enumerate("xyz"):
            row = np.asarray(frame[n], dtype=float)
            m = int(np.argmax(np.abs(row)))
            if np.isclose(abs(row[m]), 1.0):
                words[axis] = CANONICAL_WORDS[(m, int(np.sign(row[m])))]
            else:
                words[axis] = "canonical " + np.array2string(row, precision=3)
        return words

    def describe(self) -> dict:
        """The four defining parts (and storage details), in words."""
        turns = ", then ".join(f"{t.angle} about {t.axis} ({t.hand}-handed)" for t in self.turns)
        fw = self.frame_words()
        rng = ", ".join(
            f"{r} [{lo:g}, {hi:g}]" for r, (lo, hi) in ((r, self.ranges.get(r, (-180, 180))) for r in ROLES)
        )
        hand = (
            "right-handed (det +1)"
            if self.proper_frame
            else "LEFT-HANDED (det -1, improper; the system matrix B A B^T is still a proper rotation)"
        )
        frame = f"x: {fw['x']}; y: {fw['y']}; z: {fw['z']}; {hand}"
        if self.model_frame is not None:
            mw = self.frame_words(self.model_frame)
            frame += f"; head-model frame x: {mw['x']}; y: {mw['y']}; z: {mw['z']}"
        if self.angle_frame == "canonical":
            turns = "no angles of its own: angles reported are the 300W-LP angles of the same rotation"
        out = {
            "frame": frame,
            "axes": turns,
            "range": rng + f"; primary solution: {self.selection}",
            "order": f"{self.sequence} {self.axes.upper()}, "
            f"{'active' if self.storage == 'active' else 'transposed (passive)'} matrix",
            "storage": self.storage_words(),
        }
        return out

    def storage_words(self) -> str:
        cols = ", ".join(self.value_columns)
        k = self.storage_kind
        if k == "angles":
            return f"angles stored as ({', '.join(self.order)}) in {self.units}; columns {cols} ({self.value_units})"
        if k == "matrix":
            what = "rotation block of a 4x4 matrix" if self.matrix_layout == "4x4" else "3x3 matrix"
            return f"{what}, row-major, columns {cols}"
        if k == "rotvec":
            return f"rotation vector (axis * angle, radians), columns {cols}"
        if k == "quaternion":
            return (
                f"unit quaternion, {'scalar first' if self.quaternion_order == 'wxyz' else 'scalar last'} "
                f"({self.quaternion_order}; written with w >= 0), columns {cols}"
            )
        i, j = self.sixd_columns
        return (
            f"6-D: matrix column {i} then column {j} (Gram-Schmidt on input, third column by cross product), "
            f"columns {cols}"
        )

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["frame"] = [list(map(float, r)) for r in self.frame]
        if self.model_frame is not None:
            d["model_frame"] = [list(map(float, r)) for r in self.model_frame]
        d["turns"] = [dataclasses.asdict(t) for t in self.turns]
        d["order"] = list(self.order)
        d["ranges"] = {k: list(v) for k, v in self.ranges.items()}
        d["sixd_columns"] = list(self.sixd_columns)
        d["columns"] = dict(self.columns)
        d["examples"] = [dict(e) for e in self.examples]
        # the same keys the TOML layout has, so that system_from_dict(s.to_dict()) rebuilds s
        if d.pop("angle_frame", "system") == "canonical":  # no turns of its own: reports 300W-LP angles
            d.pop("turns", None)
            d.pop("sequence", None)
        if d.get("model_frame") is None:
            d.pop("model_frame", None)
        return d

    def definition(self) -> dict:
        """The mathematical definition only (no names, words or examples): equal dicts, same system."""
        d = self.to_dict()
        for k in ("name", "description", "notes", "source", "verified", "examples"):
            d.pop(k, None)
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def to_toml(self) -> str:
        """Serialise to the TOML layout that :func:`load_system` reads."""
        lines = [f'name = "{self.name}"', f'description = "{toml_escape(self.description)}"']
        if self.notes:
            lines.append(f'notes = "{toml_escape(self.notes)}"')
        for key in ("source", "verified"):
            if getattr(self, key):
                lines.append(f'{key} = "{toml_escape(getattr(self, key))}"')
        mat = lambda F: "[" + ", ".join("[" + ", ".join(format_number(v) for v in r) + "]" for r in F) + "]"
        lines += ["frame = " + mat(self.frame)]
        if self.model_frame is not None:
            lines += ["model_frame = " + mat(self.model_frame)]
        if self.angle_frame == "system":
            lines.append(f'sequence = "{self.sequence}"')
        lines += [
            f'storage = "{self.storage}"',
            "order = [" + ", ".join(f'"{o}"' for o in self.order) + "]",
            f'units = "{self.units}"',
            f'selection = "{self.selection}"',
            f"gimbal_tol = {self.gimbal_tol!r}",
            f'storage_kind = "{self.storage_kind}"',
        ]
        if self.storage_kind == "matrix":
            lines.append(f'matrix_layout = "{self.matrix_layout}"')
        if self.storage_kind == "quaternion":
            lines.append(f'quaternion_order = "{self.quaternion_order}"')
        if self.storage_kind == "6d":
            lines.append(f"sixd_columns = [{self.sixd_columns[0]}, {self.sixd_columns[1]}]")
        if self.angle_frame == "system":
            for t in self.turns:
                lines += ["", "[[turns]]", f'angle = "{t.angle}"', f'axis = "{t.axis}"', f'hand = "{t.hand}"']
        if self.ranges:
            lines += ["", "[ranges]"] + [
                f"{k} = [{format_number(lo)}, {format_number(hi)}]" for k, (lo, hi) in self.ranges.items()
            ]
        if self.columns:
            lines += ["", "[columns]"] + [f'{k} = "{toml_escape(v)}"' for k, v in self.columns.items()]
        return "\n".join(lines) + "\n"
