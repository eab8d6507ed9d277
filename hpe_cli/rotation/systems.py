"""Rotation systems: what a head-pose label means, as data.

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
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import euler as _euler
from . import soa as _soa

ROLES = ("pitch", "yaw", "roll")
SELECTIONS = ("tait_bryan", "proper", "whenet")

#: default gimbal-lock tolerance on |cos b| (radians from the lock): 1e-4 rad is
#: 0.0057 deg. Closer than that, float32-stored labels (Pose_Para, most datasets)
#: split pitch from roll with errors above ~0.05 deg.
GIMBAL_TOL = 1e-4

_DEG = 180.0 / np.pi

_CANONICAL_WORDS = {
    (0, 1): "subject's left (image right)",
    (0, -1): "subject's right (image left)",
    (1, 1): "up (towards the forehead)",
    (1, -1): "down (towards the chin)",
    (2, 1): "out of the face (towards the camera)",
    (2, -1): "into the head (away from the camera)",
}


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

    # ------------------------------------------------------------------ checks
    def __post_init__(self):
        B = np.asarray(self.frame, dtype=float)
        if B.shape != (3, 3) or not np.allclose(B @ B.T, np.eye(3), atol=1e-9):
            raise SystemError_(f"system {self.name!r}: expected an orthonormal 3x3 frame, got {self.frame}")
        if abs(np.linalg.det(B) - 1) > 1e-9:
            raise SystemError_(f"system {self.name!r}: frame must be right-handed (det +1), got det {np.linalg.det(B):.3g}")
        if len(self.turns) != 3 or sorted(t.angle for t in self.turns) != sorted(ROLES):
            raise SystemError_(f"system {self.name!r}: expected three turns, one each for pitch, yaw, roll")
        for t in self.turns:
            if t.axis not in ("x", "y", "z") or t.hand not in ("right", "left"):
                raise SystemError_(f"system {self.name!r}: bad turn {t}: axis must be x/y/z, hand right/left")
        _euler.parse_seq(self.axes)
        for attr, allowed in (("sequence", ("intrinsic", "extrinsic")), ("storage", ("active", "transposed")),
                              ("units", ("degrees", "radians")), ("selection", SELECTIONS)):
            if getattr(self, attr) not in allowed:
                raise SystemError_(f"system {self.name!r}: expected {attr} in {allowed}, got {getattr(self, attr)!r}")
        if sorted(self.order) != sorted(ROLES):
            raise SystemError_(f"system {self.name!r}: order must be a permutation of {ROLES}, got {self.order}")

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
        return (np.stack(p1, -1).reshape(shape + (3,)), np.stack(p2, -1).reshape(shape + (3,)),
                locked.reshape(shape), lock.reshape(shape))

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
        return np.array_equal(self.B, np.eye(3))

    def soa_from_angles(self, pitch, yaw, roll):
        """Stored matrix as a nested list, from 1-D angle arrays in degrees."""
        by_role = {"pitch": pitch, "yaw": yaw, "roll": roll}
        turns = self._intrinsic_turns()
        rad = [np.asarray(by_role[t.angle], dtype=np.float64) * (t.sign() * (np.pi / 180.0)) for t in turns]
        return _euler.euler_to_soa(rad[0], rad[1], rad[2], self.intrinsic_axes)

    def soa_to_angles(self, X):
        """``(primary, secondary, locked, lock)`` with the angle triples as lists ``[pitch, yaw, roll]``."""
        seq = self.intrinsic_axes
        a, b, c, lock = _euler.soa_to_euler(X, seq)
        turns = self._intrinsic_turns()
        proper = seq[0] == seq[2]
        first = {}
        for n, (t, v) in enumerate(zip(turns, (a, b, c))):
            d = v * (_DEG if t.hand == "right" else -_DEG)
            d[d <= -180.0] += 360.0  # atan2(-0.0, -1) and left hands give -180; keep (-180, 180]
            first[t.angle] = (d, n == 1)
        p1, p2 = [], []
        for role in ROLES:
            d, middle = first[role]
            p1.append(d)
            if not middle:  # the first and last turns move by 180 degrees
                d2 = d + 180.0
                d2[d > 0] -= 360.0
            elif proper:
                d2 = -d
            else:  # the middle Tait-Bryan turn goes to 180 - b
                d2 = 180.0 - d
                d2[d < 0] -= 360.0
            d2[d2 <= -180.0] += 360.0  # tiny |d| rounds d - 180 to exactly -180
            p2.append(d2)
        if self.selection == "whenet":
            ok1 = (np.abs(p1[0]) < 90) & (np.abs(p1[2]) < 90)
            ok2 = (np.abs(p2[0]) < 90) & (np.abs(p2[2]) < 90)
            swap = ~ok1 & ok2
            if swap.any():
                p1, p2 = [np.where(swap, y, x) for x, y in zip(p1, p2)], [np.where(swap, x, y) for x, y in zip(p1, p2)]
        return p1, p2, lock < self.gimbal_tol, lock

    def soa_to_canonical(self, X):
        if self.storage == "transposed":
            X = _soa.transpose(X)
        if self._identity_frame:
            return X
        B = _soa.constant(self.B)
        return _soa.mul(_soa.mul(_soa.transpose(B), X), B)

    def soa_from_canonical(self, A):
        X = A
        if not self._identity_frame:
            B = _soa.constant(self.B)
            X = _soa.mul(_soa.mul(B, A), _soa.transpose(B))
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
    def frame_words(self) -> dict:
        """The system's x, y, z axes described in words."""
        words = {}
        for n, axis in enumerate("xyz"):
            row = np.asarray(self.frame[n], dtype=float)
            m = int(np.argmax(np.abs(row)))
            if np.isclose(abs(row[m]), 1.0):
                words[axis] = _CANONICAL_WORDS[(m, int(np.sign(row[m])))]
            else:
                words[axis] = "canonical " + np.array2string(row, precision=3)
        return words

    def describe(self) -> dict:
        """The four defining parts (and storage details), in words."""
        turns = ", then ".join(f"{t.angle} about {t.axis} ({t.hand}-handed)" for t in self.turns)
        fw = self.frame_words()
        rng = ", ".join(f"{r} [{lo:g}, {hi:g}]" for r, (lo, hi) in
                        ((r, self.ranges.get(r, (-180, 180))) for r in ROLES))
        return {
            "frame": f"x: {fw['x']}; y: {fw['y']}; z: {fw['z']}",
            "axes": turns,
            "range": rng + f"; primary solution: {self.selection}",
            "order": f"{self.sequence} {self.axes.upper()}, "
                     f"{'active' if self.storage == 'active' else 'transposed (passive)'} matrix",
            "storage": f"angles stored as ({', '.join(self.order)}) in {self.units}",
        }

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["frame"] = [list(map(float, r)) for r in self.frame]
        d["turns"] = [dataclasses.asdict(t) for t in self.turns]
        d["order"] = list(self.order)
        d["ranges"] = {k: list(v) for k, v in self.ranges.items()}
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def to_toml(self) -> str:
        """Serialise to the TOML layout that :func:`load_system` reads."""
        lines = [f'name = "{self.name}"', f'description = "{_esc(self.description)}"']
        if self.notes:
            lines.append(f'notes = "{_esc(self.notes)}"')
        lines += [
            "frame = [" + ", ".join("[" + ", ".join(_num(v) for v in r) + "]" for r in self.frame) + "]",
            f'sequence = "{self.sequence}"', f'storage = "{self.storage}"',
            "order = [" + ", ".join(f'"{o}"' for o in self.order) + "]",
            f'units = "{self.units}"', f'selection = "{self.selection}"', f"gimbal_tol = {self.gimbal_tol!r}",
        ]
        for t in self.turns:
            lines += ["", "[[turns]]", f'angle = "{t.angle}"', f'axis = "{t.axis}"', f'hand = "{t.hand}"']
        if self.ranges:
            lines += ["", "[ranges]"] + [f"{k} = [{_num(lo)}, {_num(hi)}]" for k, (lo, hi) in self.ranges.items()]
        return "\n".join(lines) + "\n"


def _esc(s: str) -> str:
    return s.replace("\\", "\\\\").replace('"', '\\"')


def _num(v) -> str:
    v = float(v)
    return str(int(v)) if v.is_integer() else repr(v)


def system_from_dict(d: dict, source: str = "<dict>") -> RotationSystem:
    """Build a system from a parsed TOML/JSON mapping; errors name ``source``."""
    try:
        turns = tuple(Turn(str(t["angle"]), str(t["axis"]).lower(), str(t.get("hand", "right")))
                      for t in d["turns"])
        ranges = {str(k): (float(v[0]), float(v[1])) for k, v in d.get("ranges", {}).items()}
        return RotationSystem(
            name=str(d["name"]),
            description=str(d.get("description", "")),
            frame=tuple(tuple(float(x) for x in row) for row in d.get("frame", np.eye(3).tolist())),
            turns=turns,
            sequence=str(d.get("sequence", "intrinsic")),
            storage=str(d.get("storage", "active")),
            order=tuple(d.get("order", ROLES)),
            units=str(d.get("units", "degrees")),
            ranges=ranges,
            selection=str(d.get("selection", "proper" if turns[0].axis == turns[2].axis else "tait_bryan")),
            gimbal_tol=float(d.get("gimbal_tol", GIMBAL_TOL)),
            notes=str(d.get("notes", "")),
        )
    except SystemError_ as exc:
        raise SystemError_(f"{source}: {exc}") from None
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise SystemError_(f"{source}: invalid system definition ({type(exc).__name__}: {exc})") from None


def load_system(path) -> RotationSystem:
    """Read a system definition from a TOML file."""
    import tomllib

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SystemError_(f"{path}: no such system file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SystemError_(f"{path}: not valid TOML ({exc})") from None
    return system_from_dict(data, str(path))


def _builtin_dir():
    """``configs/systems``: package data when installed, the repository folder in a source tree."""
    from importlib.resources import files

    source_tree = Path(__file__).resolve().parents[2] / "configs" / "systems"
    if source_tree.is_dir():  # hpe_cli imported from a checkout: its own configs, not an installed copy's
        return source_tree
    return files("hpe_cli.configs") / "systems"


_CACHE: dict = {}


def builtin_systems() -> dict:
    """All built-in systems, by name (read once from ``configs/systems``)."""
    if not _CACHE:
        import tomllib

        for entry in sorted(_builtin_dir().iterdir(), key=lambda p: p.name):
            if entry.name.endswith(".toml"):
                sysm = system_from_dict(tomllib.loads(entry.read_text(encoding="utf-8")), entry.name)
                _CACHE[sysm.name] = sysm
    return dict(_CACHE)


def system_names() -> list:
    return list(builtin_systems())


def get_system(spec) -> RotationSystem:
    """A built-in system by name, a TOML file path, or a ``RotationSystem`` as is."""
    if isinstance(spec, RotationSystem):
        return spec
    spec = str(spec)
    systems = builtin_systems()
    if spec in systems:
        return systems[spec]
    if spec.endswith(".toml") or Path(spec).is_file():
        return load_system(spec)
    raise SystemError_(f"expected a system name ({', '.join(systems)}) or a .toml file, got {spec!r}")
