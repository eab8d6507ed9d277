"""``hpe infer``'s settings: one :class:`InferOptions`, built by the command line and the Python API alike."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import UsageError

ROLE_NAMES = ("pitch", "yaw", "roll")
#: ``--rotations KIND:COLS``: the stored kinds a data table's rotations may have, and their number of columns
ROTATION_KINDS = {"rotvec": 3, "quaternion-wxyz": 4, "quaternion-xyzw": 4, "6d": 6}
RETURNS = ("angles", "stored")
LANDMARK_FRAMES = ("image", "canonical", "opencv")
STORAGES = ("active", "transposed")
#: ``--samples``: the range of samples the code is called on
SAMPLES_RANGE = (16, 100_000)


def _check_roles(roles, what: str):
    if sorted(roles) != sorted(ROLE_NAMES):
        raise UsageError(f"{what}: expected the three roles pitch, yaw, roll in some order, got {list(roles)!r}")


@dataclass(frozen=True)
class InferOptions:
    """The settings of one ``hpe infer`` run (its options, by the same names).

    Attributes
    ----------
    builder : bool
        The code is a ``--callable`` (angles -> matrix); else a ``--decoder`` (matrix -> angles or values).
    returns : str
        ``"angles"`` or ``"stored"`` (a decoder returning a rotation vector, quaternion, 6-D vector or matrix).
    roles : tuple of str
        The role of each argument (``--callable``) or returned angle (``--decoder``): pitch, yaw, roll in some
        order.
    packed : bool
        ``--callable`` takes one sequence of the three angles.
    units : {None, "deg", "rad"}
        Angle units (None: radians for code, degrees for tables).
    angle_columns : (roles, columns), optional
        A data table's angle columns in storage order (None: ``pitch, yaw, roll``).
    matrix : list of 9 str, optional
        A data table's matrix columns (None: ``r00..r22`` when present).
    rotations : (kind, columns), optional
        A data table's stored rotations, ``kind`` one of :data:`ROTATION_KINDS` (None: ``rx,ry,rz`` or
        ``qw,qx,qy,qz`` when present and ``r00..r22`` are not).
    landmarks3d : str, optional
        Prefix of a table's 68 3-D landmark columns ``PREFIX{i}_x/_y/_z``.
    landmark_frame : str
        Their axes: ``image``, ``canonical`` or ``opencv``.
    tol : float, optional
        Largest Frobenius error counted as equal, > 0 (None: 1e-6 for code, 1e-4 for tables).
    samples : int, optional
        Samples to call the code on, 16..100000 (None: 64 for a callable, 256 for a decoder).
    seed : int
        Random seed of the samples.
    name, frame, storage
        A custom answer's name, frame (a :class:`RotationSystem` frame) and matrix meaning (``active`` or
        ``transposed``).
    timeout : float, optional
        Seconds the code may run, finite and > 0 (None: 60).
    import_path : tuple of str
        Folders to import ``module:FUNC`` from.
    rejects, strict, overwrite
        ``--rejects FILE``, ``--strict``, ``--overwrite``.
    threads : int, optional
        >= 1 (None: one per core, at most 8). A data table: the size of OpenCV's and pyarrow's thread pools for
        the run. Code: ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` and ``OPENBLAS_NUM_THREADS`` of the child process
        before the code is imported (so torch and BLAS libraries it loads start that many threads); without
        ``threads`` a value already in the environment is kept. The search itself runs on one Python thread,
        and the report is the same whatever the number.
    """

    builder: bool = False
    returns: str = "angles"
    roles: tuple = ROLE_NAMES
    packed: bool = False
    units: str | None = None
    angle_columns: tuple | None = None
    matrix: tuple | None = None
    rotations: tuple | None = None
    landmarks3d: str | None = None
    landmark_frame: str = "image"
    tol: float | None = None
    samples: int | None = None
    seed: int = 0
    name: str | None = None
    frame: object = None
    storage: str = "active"
    timeout: float | None = None
    import_path: tuple = ()
    rejects: object = None
    strict: bool = False
    overwrite: bool = False
    threads: int | None = None

    def __post_init__(self):
        for what, value, allowed in (
            ("returns", self.returns, RETURNS),
            ("units", self.units, (None, "deg", "rad")),
            ("landmark_frame", self.landmark_frame, LANDMARK_FRAMES),
            ("storage", self.storage, STORAGES),
        ):
            if value not in allowed:
                raise UsageError(f"{what}: expected one of {', '.join(map(str, allowed))}, got {value!r}")
        _check_roles(self.roles, "roles")
        if self.angle_columns is not None:
            _check_roles(self.angle_columns[0], "angle_columns")
            if len(self.angle_columns[1]) != 3:
                raise UsageError(f"angle_columns: expected 3 columns, got {len(self.angle_columns[1])}")
        if self.matrix is not None and len(self.matrix) != 9:
            raise UsageError(f"matrix: expected 9 columns, got {len(self.matrix)}")
        if self.rotations is not None:
            kind, cols = self.rotations
            if kind not in ROTATION_KINDS or len(cols) != ROTATION_KINDS[kind]:
                raise UsageError(
                    f"rotations: expected (KIND, COLUMNS) with KIND one of {', '.join(ROTATION_KINDS)} and its "
                    f"number of columns, got {self.rotations!r}"
                )
        if self.tol is not None and self.tol <= 0:  # as --tol's range
            raise UsageError(f"tol: expected a number > 0, got {self.tol}")
        if self.samples is not None and not SAMPLES_RANGE[0] <= self.samples <= SAMPLES_RANGE[1]:
            raise UsageError(f"samples: expected {SAMPLES_RANGE[0]}..{SAMPLES_RANGE[1]}, got {self.samples}")
        if self.timeout is not None and not (math.isfinite(self.timeout) and self.timeout > 0):
            raise UsageError(f"timeout: expected a positive finite number of seconds, got {self.timeout!r}")
        t = self.threads
        if t is not None and (not isinstance(t, int) or isinstance(t, bool) or t < 1):
            raise UsageError(f"threads: expected an integer >= 1 (or None: one per core), got {t!r}")
        if self.packed and not self.builder:
            raise UsageError("packed: applies to a callable (builder=True) only")
