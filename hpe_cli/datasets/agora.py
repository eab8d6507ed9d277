"""AGORA ground-truth dataframes (``*_withjv.pkl``, SPEC §7).

AGORA ships one pandas DataFrame per split chunk, pickled. Each row is one
image; per-person fields are lists with one entry per person:

- ``imgPath`` (str), and per person ``isValid`` (bool: occlusion in 0-90),
  ``occlusion`` (percent, 0-100), ``gt_joints_2d`` (J, 2) pixels,
  ``gt_joints_3d`` (J, 3) metres in the OpenCV camera frame (x right, y down,
  z forward), J = 127 SMPL-X joints (144 with the face contour);
- DirectMHP's re-export adds, per person, ``cam_j3d`` (J, 3) the joints in the
  body's own frame (metres), ``camR`` (3, 3), ``camT`` (3, 1) and ``camK``
  (3, 3) with ``camR @ cam_j3d + camT = gt_joints_3d``;
- also ``X, Y, Z, Yaw`` (person placement), ``camX, camY, camZ, camYaw``,
  ``gender``, ``kid``, ``age``, ``gt_path_smpl(x)``, ``gt_verts``, unused here.

SMPL-X joints 76..126 are the 51 iBUG-68 points 17..67 (brows, nose, eyes,
mouth; no jaw line). :func:`read_agora` flattens a dataframe to one entry per
person with numpy arrays, ready for the vectorised relabelling. It prefers
DirectMHP's camera columns; a dataframe without them but with ``gt_joints_3d``
(AGORA's own release) is read in the camera frame (identity extrinsics) with
the intrinsics rebuilt by AGORA's rule (:func:`agora_intrinsics`).

Pickles are loaded through a restricted unpickler (:func:`load_dataframe`)
that builds only the pandas, numpy and pyarrow objects a dataframe is made of;
a pickle that asks for anything else is refused, with the one-line command
that converts it once to Parquet (which hpe reads too). ``trust=True``
(``--trust-pickle``) lifts the restriction for files you trust. Files are
recognised by content (pickle, Parquet), not by extension.

Everything read is validated at the door. Types and shapes first: a field
that is not what AGORA stores (``cam_j3d`` or ``occlusion`` given as a string,
``isValid`` as ``'no'``, ``imgPath`` as None, ``camR`` as a ragged list) raises
:class:`~hpe_cli.errors.HpeError` naming the file, the row (0-based, as the
output's ``row`` column), the person and the field:
``FILE: row 3, person 0: cam_j3d: expected a (J, 3) array of numbers ..., got str 'abc'``.
Then values, per person: ``camR`` finite, orthonormal and of determinant +1;
``camT`` finite and below 1e6 m; ``camK`` finite, ``[[fx, s, cx], [0, fy, cy],
[0, 0, 1]]`` with positive focal lengths and a positive principal point;
``occlusion`` within 0-100 (or missing); joints smaller than 1e6 in magnitude
(NaN is a missing point); ``imgPath`` a relative path without ``..`` or NUL.
A person that fails gets the reason, starting with the field, in
:attr:`AgoraPeople.reason` (and no label), never an exception; ``hpe
relabel-agora`` without ``--rejects`` refuses the file on such a person.
"""

from __future__ import annotations

import importlib
import pickle
import warnings
from dataclasses import dataclass
from itertools import chain
from pathlib import Path

import numpy as np

from ..errors import HpeError
from ..rotation.check import rotation_screen_columns
from .fields import as_bool, as_numbers, describe

#: first SMPL-X joint of the 51 face landmarks (iBUG-68 point 17)
FACE_FIRST = 76
FACE_COUNT = 51
#: columns always needed; then either CAMERA_COLS or gt_joints_3d
BASE_COLS = ("imgPath", "isValid", "occlusion")
CAMERA_COLS = ("cam_j3d", "camR", "camT", "camK")
#: AGORA's render camera (``agora_evaluation/projection.py``): a 36 x 20.25 mm sensor, principal point at the centre
SENSOR_MM = (36.0, 20.25)
#: AGORA's focal lengths (mm) by scene, matched on the image name in this order; otherwise 28 mm
SCENE_FOCAL_MM = (("hdri", 50.0), ("cam00", 18.0), ("cam01", 18.0), ("cam02", 18.0), ("cam03", 18.0), ("ag2", 28.0))
DEFAULT_FOCAL_MM = 28.0
#: AGORA's full-resolution images
AGORA_SIZE = (3840, 2160)
#: tolerance of the camR rotation test (||R R^T - I||_F and |det R - 1|)
CAM_R_TOL = 1e-6
#: joints at or beyond this magnitude (metres) are absurd
MAX_JOINT = 1e6

#: the globals a pandas DataFrame pickle may name (module, name), after pandas' own renames of old paths
SAFE_GLOBALS = frozenset(
    {
        ("builtins", "slice"),
        ("builtins", "bytearray"),
        ("builtins", "complex"),
        ("builtins", "set"),
        ("builtins", "frozenset"),
        ("builtins", "range"),
        ("builtins", "object"),
        ("copyreg", "_reconstructor"),
        ("numpy", "ndarray"),
        ("numpy", "dtype"),
        ("numpy", "bool_"),
        ("numpy._core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "scalar"),
        ("numpy._core.numeric", "_frombuffer"),
        ("numpy.core.multiarray", "_reconstruct"),
        ("numpy.core.multiarray", "scalar"),
        ("numpy.core.numeric", "_frombuffer"),
        ("pandas", "DataFrame"),
        ("pandas", "Series"),
        ("pandas", "Index"),
        ("pandas", "RangeIndex"),
        ("pandas", "StringDtype"),
        ("pandas.core.frame", "DataFrame"),
        ("pandas.core.series", "Series"),
        ("pandas.core.indexes.base", "_new_Index"),
        ("pandas.core.indexes.base", "Index"),
        ("pandas.core.indexes.range", "RangeIndex"),
        ("pandas.core.indexes.numeric", "Int64Index"),
        ("pandas.core.indexes.numeric", "Float64Index"),
        ("pandas.core.indexes.numeric", "UInt64Index"),
        ("pandas.core.internals.managers", "BlockManager"),
        ("pandas.core.internals.managers", "SingleBlockManager"),
        ("pandas.core.internals.blocks", "new_block"),
        ("pandas.core.internals.blocks", "Block"),
        ("pandas.core.internals.blocks", "ObjectBlock"),
        ("pandas.core.internals.blocks", "FloatBlock"),
        ("pandas.core.internals.blocks", "IntBlock"),
        ("pandas.core.internals.blocks", "BoolBlock"),
        ("pandas.core.internals.blocks", "NumpyBlock"),
        ("pandas._libs.internals", "_unpickle_block"),
        ("pandas.arrays", "ArrowStringArray"),
        ("pandas.arrays", "StringArray"),
        ("pandas.core.arrays.string_", "StringDtype"),
        ("pandas.core.arrays.string_", "StringArray"),
        ("pandas.core.arrays.string_arrow", "ArrowStringArray"),
        ("pyarrow.lib", "_restore_array"),
        ("pyarrow.lib", "py_buffer"),
        ("pyarrow.lib", "type_for_alias"),
    }
)

#: how to turn a trusted AGORA pickle into Parquet once (nested lists instead of numpy arrays)
TO_PARQUET = (
    'python -c "import sys, numpy as np, pandas as pd; '
    "f = lambda v: v.tolist() if isinstance(v, np.ndarray) else [f(x) for x in v] "
    "if isinstance(v, (list, tuple)) else v; "
    "df = pd.read_pickle(sys.argv[1]); "
    "df = df.apply(lambda c: c.map(f) if c.dtype == object else c); "
    'df.to_parquet(sys.argv[2])" IN.pkl OUT.parquet'
)


@dataclass
class AgoraPeople:
    """All people of one dataframe, one entry per person (N people).

    Attributes
    ----------
    source : Path
    row : ndarray of int (N,)
        Row of the dataframe (one image per row).
    person : ndarray of int (N,)
        Index of the person in that row's lists.
    image : ndarray of object (N,)
        ``imgPath``.
    valid : ndarray of bool (N,)
        ``isValid``.
    occlusion : ndarray of float (N,)
        Percent occluded (NaN when the value is missing).
    face3d : ndarray (N, 51, 3)
        The 51 face joints in the frame of ``cam_R``/``cam_t`` (metres).
    cam_R, cam_t, K : ndarray (N, 3, 3), (N, 3), (N, 3, 3)
        ``cam_R @ face3d + cam_t`` is the OpenCV camera frame; ``K`` in the
        pixels of the resolution the dataframe was built for.
    frame : {"body", "camera"}
        ``body``: DirectMHP's ``cam_j3d`` + camera columns; ``camera``:
        ``gt_joints_3d`` with identity extrinsics and AGORA's intrinsics.
    images : int
        Rows (images) in the dataframe.
    reason : ndarray of object (N,)
        '' for a usable person, else why not (bad camera, joints or image
        path); set by :func:`read_agora`, which also replaces the unusable
        geometry by NaN.
    """

    source: Path
    row: np.ndarray
    person: np.ndarray
    image: np.ndarray
    valid: np.ndarray
    occlusion: np.ndarray
    face3d: np.ndarray
    cam_R: np.ndarray
    cam_t: np.ndarray
    K: np.ndarray
    frame: str
    images: int
    reason: object = None

    def __len__(self) -> int:
        return len(self.row)


def _sniff(path: Path) -> str:
    with open(path, "rb") as f:
        head = f.read(8)
    if head[:4] == b"PAR1":
        return "parquet"
    if head[:1] == b"\x80":
        return "pickle"
    return "other"


def _restricted_unpickler(fh, path):

    try:
        from pandas.compat.pickle_compat import _class_locations_map as renames
    except ImportError:  # pragma: no cover - pandas without the map
        renames = {}

    class RestrictedUnpickler(pickle.Unpickler):
        def find_class(self, module, name):
            module, name = renames.get((module, name), (module, name))
            if (module, name) not in SAFE_GLOBALS:
                raise HpeError(
                    f"{path}: refused to load the pickle: it asks for {module}.{name}, which is not "
                    "part of a pandas DataFrame (a pickle can run code). If you trust the file, "
                    "pass --trust-pickle, or convert it once to Parquet and give the .parquet: " + TO_PARQUET
                )

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return getattr(importlib.import_module(module), name)

    return RestrictedUnpickler(fh)


def load_dataframe(path, trust: bool = False):
    """Load an AGORA dataframe from a pickle (restricted unless ``trust``) or a Parquet file.

    The file's kind is read from its first bytes, whatever its extension.
    A pickle is unpickled by a restricted unpickler that only builds
    pandas/numpy/pyarrow data objects (see :data:`SAFE_GLOBALS`); with
    ``trust=True`` any pickle is loaded (**this runs code stored in the
    file**: trusted files only).
    """
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise HpeError(f"{path}: no such file")
    kind = _sniff(path)
    try:
        if kind == "parquet":
            import pyarrow.parquet as pq

            table = pq.read_table(path)
            df = pd.DataFrame({name: table.column(name).to_pylist() for name in table.column_names})
        elif kind == "pickle":
            if trust:
                df = pd.read_pickle(path)
            else:
                with open(path, "rb") as fh:
                    df = _restricted_unpickler(fh, path).load()
        else:
            raise HpeError(
                f"{path}: expected an AGORA dataframe as a pandas pickle or Parquet file, got "
                "neither (checked by content)"
            )
    except HpeError:
        raise
    except Exception as exc:  # unpickling raises anything: EOFError, UnpicklingError, TypeError...
        raise HpeError(
            f"{path}: cannot load the {'Parquet file' if kind == 'parquet' else 'pickle'} "
            f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]})"
        ) from None
    if not isinstance(df, pd.DataFrame):
        raise HpeError(f"{path}: expected a pandas DataFrame (AGORA *_withjv.pkl), got {type(df).__name__}")
    return df


def check_columns(df, path) -> str:
    """Check the needed columns; return ``"body"`` or ``"camera"`` (see :class:`AgoraPeople`)."""
    for col in BASE_COLS:
        if col not in df.columns:
            raise HpeError(f"{path}: missing column {col!r} (expected an AGORA *_withjv.pkl ground-truth dataframe)")
    missing = [c for c in CAMERA_COLS if c not in df.columns]
    if not missing:
        return "body"
    if "gt_joints_3d" in df.columns:
        return "camera"
    raise HpeError(
        f"{path}: missing column {missing[0]!r} (and no 'gt_joints_3d' to use instead; "
        "expected an AGORA *_withjv.pkl ground-truth dataframe)"
    )


def agora_intrinsics(images, width: int, height: int) -> np.ndarray:
    """AGORA's render intrinsics for images of ``width`` x ``height`` pixels.

    ``fx = f / 36 mm * width``, ``fy = f / 20.25 mm * height``, principal
    point at ``(width / 2, height / 2)``, with the focal length ``f`` of the
    scene named in the image path (:data:`SCENE_FOCAL_MM`, else 28 mm).

    Returns
    -------
    ndarray (N, 3, 3)
    """
    names = np.asarray(images, dtype=object).astype(str)
    f = np.full(names.shape, DEFAULT_FOCAL_MM)
    done = np.zeros(names.shape, dtype=bool)
    for key, mm in SCENE_FOCAL_MM:
        hit = ~done & (np.char.find(names, key) >= 0)
        f[hit] = mm
        done |= hit
    K = np.zeros(names.shape + (3, 3))
    K[..., 0, 0] = f / SENSOR_MM[0] * width
    K[..., 1, 1] = f / SENSOR_MM[1] * height
    K[..., 0, 2] = width / 2.0
    K[..., 1, 2] = height / 2.0
    K[..., 2, 2] = 1.0
    return K


def _as_list(value):
    """A per-person cell as a list (AGORA leaves '' or NaN where nothing was stored)."""
    if isinstance(value, (list, tuple)):
        return list(value)
    if isinstance(value, np.ndarray):
        return list(value) if value.ndim else [value.item()]
    if value is None or (isinstance(value, str) and value == "") or (isinstance(value, float) and np.isnan(value)):
        return []
    return [value]


def _where(path, rows, persons, n) -> str:
    return f"{path}: row {rows[n]}, person {persons[n]}"


def _person_arrays(path, col, flat, rows, persons, shape, want):
    """Stack one per-person array column into ``(N, *shape)`` float64 (``-1`` in ``shape``: any length,
    at least 127 joints), checking every entry's type and shape at the door.

    Raises ``FILE: row R, person P: COL: expected WANT, got ...`` for the first entry that is not
    numbers of that shape (a string, None, a nested or ragged list, objects).
    """

    if not flat:
        return np.zeros((0,) + tuple(FACE_FIRST + FACE_COUNT if s == -1 else s for s in shape))
    fixed = all(s != -1 for s in shape)
    if fixed and all(isinstance(a, np.ndarray) and a.dtype.kind in "fiu" and a.shape == shape for a in flat):
        return np.stack(flat).astype(np.float64, copy=False)  # the common case: one stack, no per-entry work
    out = []
    for n, a in enumerate(flat):
        arr, got = as_numbers(a, shape)
        if arr is not None and not fixed and arr.shape[0] < FACE_FIRST + FACE_COUNT:
            arr, got = None, f"got shape {arr.shape}"
        if arr is None:
            raise HpeError(f"{_where(path, rows, persons, n)}: {col}: expected {want}, {got}")
        out.append(arr[FACE_FIRST : FACE_FIRST + FACE_COUNT] if not fixed else arr)
    return np.stack(out)


def _person_translations(path, col, flat, rows, persons):
    """``camT`` entries (3, 1), (1, 3) or (3,) as (N, 3)."""

    out = np.empty((len(flat), 3))
    for n, a in enumerate(flat):
        arr, got = as_numbers(a)
        if arr is not None and arr.size != 3:
            arr, got = None, f"got shape {arr.shape}"
        if arr is None:
            raise HpeError(f"{_where(path, rows, persons, n)}: {col}: expected 3 numbers (a (3, 1) translation), {got}")
        out[n] = arr.reshape(3)
    return out


def _person_flags(path, flat, rows, persons) -> np.ndarray:
    """``isValid`` entries as bools: True/False (numpy bools, 0/1 too); 'no', None, numbers refused."""

    if all(isinstance(v, (bool, np.bool_)) for v in flat):
        return np.array(flat, dtype=bool).reshape(-1)
    out = np.empty(len(flat), dtype=bool)
    for n, v in enumerate(flat):
        b, got = as_bool(v)
        if b is None:
            raise HpeError(f"{_where(path, rows, persons, n)}: isValid: expected True or False, {got}")
        out[n] = b
    return out


def _person_occlusion(path, flat, rows, persons) -> np.ndarray:
    """``occlusion`` entries as floats (None/NaN: unknown); strings, bools and arrays refused."""

    out = np.empty(len(flat))
    for n, v in enumerate(flat):
        if v is None:
            out[n] = np.nan
        elif isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)):
            out[n] = float(v)
        else:
            raise HpeError(
                f"{_where(path, rows, persons, n)}: occlusion: expected a percentage (a number "
                f"0-100), got {describe(v)}"
            )
    return out


def _image_paths(path, values) -> np.ndarray:
    """``imgPath`` per row: a string (checked for traversal later, per person); None, numbers refused."""

    for k, v in enumerate(values):
        if not isinstance(v, str):
            raise HpeError(f"{path}: row {k}: imgPath: expected a string (the image's path), got {describe(v)}")
    return np.asarray(values, dtype=object)


def unsafe_name(name: str) -> str:
    """Why a name from a file cannot become a path or an ``image`` value ('' when it can)."""
    if not isinstance(name, str) or not name:
        return "empty image path"
    if "\x00" in name:
        return "image path contains NUL"
    p = name.replace("\\", "/")
    if p.startswith("/") or (len(p) > 1 and p[1] == ":"):
        return "absolute image path"
    if ".." in p.split("/"):
        return "image path contains '..'"
    return ""


def _validate(people) -> np.ndarray:
    """Per-person reasons ('' when usable); unusable geometry is replaced by NaN so nothing downstream fails."""

    n = len(people.row)
    reason = np.full(n, "", dtype=object)

    def mark(mask, why):
        new = mask & (reason == "")
        reason[new] = why

    names = [unsafe_name(x) for x in people.image.tolist()]
    for k, why in enumerate(names):
        if why:
            reason[k] = f"imgPath: {why}"
    with np.errstate(invalid="ignore", over="ignore"):
        occ = people.occlusion
        mark(~np.isnan(occ) & ~((occ >= 0) & (occ <= 100)), "occlusion out of range (expected a percentage 0-100)")
        R = people.cam_R
        fin = np.isfinite(R).all(axis=(1, 2))
        _, ortho, proper = rotation_screen_columns([R[:, i, j] for i in range(3) for j in range(3)], CAM_R_TOL)
        mark(~fin, "camR not finite (expected a rotation matrix)")
        mark(fin & ~ortho, f"camR not orthonormal (expected a rotation matrix: ||R R^T - I|| <= {CAM_R_TOL:g}, det +1)")
        mark(fin & ortho & ~proper, "camR determinant is not +1 (a reflection; expected a rotation matrix)")
        tfin = np.isfinite(people.cam_t).all(axis=1)
        mark(~tfin, "camT not finite (expected a translation in metres)")
        mark(
            tfin & ~(np.abs(people.cam_t) < MAX_JOINT).all(axis=1),
            "camT |value| >= 1e6 (expected a translation in metres)",
        )
        K = people.K
        if people.frame == "body":
            kfin = np.isfinite(K).all(axis=(1, 2))
            mark(~kfin, "camK not finite (expected intrinsics)")
            mark(kfin & ~((K[:, 0, 0] > 0) & (K[:, 1, 1] > 0)), "camK focal length not positive (expected fx, fy > 0)")
            pinhole = (K[:, 2, 0] == 0) & (K[:, 2, 1] == 0) & (K[:, 2, 2] == 1) & (K[:, 1, 0] == 0)
            mark(kfin & ~pinhole, "camK not a pinhole matrix (expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]])")
            mark(
                kfin & ~((K[:, 0, 2] > 0) & (K[:, 1, 2] > 0)),
                "camK principal point not positive (expected cx, cy > 0: AGORA puts it at the image centre)",
            )
        f = people.face3d
        jbad = (np.abs(f) >= MAX_JOINT).any(axis=(1, 2))  # inf included; NaN is a missing point, fit_faces' job
        mark(jbad, "face joints infinite or |value| >= 1e6")
    bad = reason != ""
    if bad.any():
        people.cam_R[bad] = np.eye(3)
        people.cam_t[bad] = 0.0
        people.face3d[bad] = np.nan
        if people.frame == "body":
            people.K[bad] = np.nan
        people.image[bad] = [repr(x)[:200] if unsafe_name(x) else x for x in people.image[bad].tolist()]
    return reason


def read_agora(path, df=None, trust: bool = False) -> AgoraPeople:
    """Read one AGORA ``*_withjv.pkl`` into per-person arrays (:class:`AgoraPeople`).

    Parameters
    ----------
    path : str or Path
        The pickle (restricted unpickler, see :func:`load_dataframe`) or Parquet file.
    df : pandas.DataFrame, optional
        The already-loaded dataframe (``path`` is then only used in messages).
    trust : bool
        Load any pickle (``--trust-pickle``).
    """
    path = Path(path)
    if df is None:
        df = load_dataframe(path, trust)
    frame = check_columns(df, path)
    rows = np.arange(len(df))
    valid_cells = [_as_list(v) for v in df["isValid"].tolist()]
    counts = np.array([len(c) for c in valid_cells], dtype=np.int64)
    row = np.repeat(rows, counts)
    person = np.concatenate([np.arange(c) for c in counts]) if len(counts) else np.zeros(0, dtype=np.int64)
    image = np.repeat(_image_paths(path, df["imgPath"].tolist()), counts)

    raw_valid = df["isValid"].tolist()

    def per_person(col):

        raw = df[col].tolist()
        cells = [_as_list(v) for v in raw]
        lens = np.array([len(c) for c in cells], dtype=np.int64)
        if (lens != counts).any():
            k = int(np.flatnonzero(lens != counts)[0])
            got = "" if isinstance(raw[k], (list, tuple, np.ndarray)) else f" ({describe(raw[k])})"
            iv = "" if isinstance(raw_valid[k], (list, tuple, np.ndarray)) else f", which is {describe(raw_valid[k])}"
            raise HpeError(
                f"{path}: row {k}: column {col!r} has {lens[k]} entries{got}, expected {counts[k]} "
                f"(one per person, as in isValid{iv})"
            )
        return list(chain.from_iterable(cells))

    valid = _person_flags(path, list(chain.from_iterable(valid_cells)), row, person)
    occ = _person_occlusion(path, per_person("occlusion"), row, person)
    joints = "a (J, 3) array of numbers (J = 127 or more SMPL-X joints)"
    if frame == "body":
        face3d = _person_arrays(path, "cam_j3d", per_person("cam_j3d"), row, person, (-1, 3), joints)
        cam_R = _person_arrays(path, "camR", per_person("camR"), row, person, (3, 3), "a (3, 3) array of numbers")
        cam_t = _person_translations(path, "camT", per_person("camT"), row, person)
        K = _person_arrays(path, "camK", per_person("camK"), row, person, (3, 3), "a (3, 3) array of numbers")
    else:
        face3d = _person_arrays(path, "gt_joints_3d", per_person("gt_joints_3d"), row, person, (-1, 3), joints)
        n = len(row)
        cam_R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        cam_t = np.zeros((n, 3))
        K = np.full((n, 3, 3), np.nan)  # rebuilt for the requested image size by the caller
    people = AgoraPeople(path, row, person, image, valid, occ, face3d, cam_R, cam_t, K, frame, len(df))
    people.reason = _validate(people)
    return people


def intrinsics_for_size(people: AgoraPeople, width: int, height: int):
    """Intrinsics of every person for ``width`` x ``height`` images, and the scale from the stored ones.

    With DirectMHP's ``camK`` the stored resolution is read from the principal
    point (AGORA puts it at the image centre: ``(w/2, h/2)``) and ``K`` is
    rescaled to the requested size -- AGORA's own advice for 1280x720 images is
    to scale its 3840x2160 pixels by 720/2160. Without ``camK`` the intrinsics
    are :func:`agora_intrinsics`.

    Returns
    -------
    K : ndarray (N, 3, 3)
    factor : ndarray (N, 2)
        ``(sx, sy)`` applied to the stored ``camK`` (1 when rebuilt).

    Raises
    ------
    HpeError
        When a stored principal point does not scale to the centre of a
        ``width`` x ``height`` image (another aspect ratio).
    """
    n = len(people)
    if people.frame == "camera":
        return agora_intrinsics(people.image, width, height), np.ones((n, 2))
    K = people.K
    cx, cy = K[:, 0, 2], K[:, 1, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        sx, sy = (width / 2.0) / cx, (height / 2.0) / cy
    bad = ~(np.isfinite(sx) & np.isfinite(sy) & (sx > 0) & (np.abs(sx - sy) <= 1e-3 * np.abs(sx)))
    reason = getattr(people, "reason", None)
    if reason is not None:
        bad &= reason == ""  # already rejected at the door
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise HpeError(
            f"{people.source}: row {people.row[k]}: camK's principal point ({cx[k]:g}, {cy[k]:g}) "
            f"is not at the centre of a {width}x{height} image nor of any image with that aspect "
            "ratio; expected --image-size to match the images the dataframe was built for"
        )
    S = np.zeros((n, 3, 3))
    S[:, 0, 0], S[:, 1, 1], S[:, 2, 2] = sx, sy, 1.0
    return S @ K, np.stack([sx, sy], axis=1)
