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

**Loading a pickle runs code stored in it**: read only dataframes you trust.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import chain
from pathlib import Path

import numpy as np

from ..errors import HpeError

#: first SMPL-X joint of the 51 face landmarks (iBUG-68 point 17)
FACE_FIRST = 76
FACE_COUNT = 51
#: columns always needed; then either CAMERA_COLS or gt_joints_3d
BASE_COLS = ("imgPath", "isValid", "occlusion")
CAMERA_COLS = ("cam_j3d", "camR", "camT", "camK")
#: AGORA's render camera (``agora_evaluation/projection.py``): a 36 x 20.25 mm sensor, principal point at the centre
SENSOR_MM = (36.0, 20.25)
#: AGORA's focal lengths (mm) by scene, matched on the image name in this order; otherwise 28 mm
SCENE_FOCAL_MM = (("hdri", 50.0), ("cam00", 18.0), ("cam01", 18.0), ("cam02", 18.0), ("cam03", 18.0),
                  ("ag2", 28.0))
DEFAULT_FOCAL_MM = 28.0
#: AGORA's full-resolution images
AGORA_SIZE = (3840, 2160)


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

    def __len__(self) -> int:
        return len(self.row)


def load_dataframe(path):
    """Unpickle an AGORA dataframe. **This runs code stored in the file**: trusted files only."""
    import pandas as pd

    path = Path(path)
    try:
        df = pd.read_pickle(path)
    except FileNotFoundError:
        raise HpeError(f"{path}: no such file") from None
    except Exception as exc:  # unpickling raises anything: EOFError, UnpicklingError, ModuleNotFoundError...
        raise HpeError(f"{path}: cannot load the pickle ({type(exc).__name__}: "
                       f"{' '.join(str(exc).split())[:160]})") from None
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
    raise HpeError(f"{path}: missing column {missing[0]!r} (and no 'gt_joints_3d' to use instead; "
                   "expected an AGORA *_withjv.pkl ground-truth dataframe)")


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


def _stack(path, col, cells, counts, shape, rows):
    """Stack per-person arrays of one column into (N, *shape), checking shapes."""
    flat = list(chain.from_iterable(cells))
    if len(flat) != int(counts.sum()):
        lens = np.array([len(c) for c in cells])
        k = int(np.flatnonzero(lens != counts)[0])
        raise HpeError(f"{path}: row {rows[k]}: column {col!r} has {lens[k]} entries, expected {counts[k]} "
                       "(one per person)")
    if not flat:
        return np.zeros((0,) + shape)
    try:
        arr = np.stack([np.asarray(a, dtype=np.float64) for a in flat])
    except (ValueError, TypeError):
        arr = None
    if arr is None or arr.shape[1:] != shape:
        for n, a in enumerate(flat):
            a = np.asarray(a)
            if a.shape != shape:
                k = int(np.searchsorted(np.cumsum(counts), n, side="right"))
                raise HpeError(f"{path}: row {rows[k]}: column {col!r} holds an array of shape {a.shape}, "
                               f"expected {shape}")
    return arr


def _joints(path, col, cells, counts, rows, dim):
    """The 51 face joints of every person from a (J, dim) joints column."""
    flat = list(chain.from_iterable(cells))
    if len(flat) != int(counts.sum()):
        return _stack(path, col, cells, counts, (FACE_COUNT, dim), rows)  # raises the count error
    out = np.empty((len(flat), FACE_COUNT, dim))
    for n, a in enumerate(flat):
        a = np.asarray(a, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != dim or a.shape[0] < FACE_FIRST + FACE_COUNT:
            k = int(np.searchsorted(np.cumsum(counts), n, side="right"))
            raise HpeError(f"{path}: row {rows[k]}: column {col!r} holds joints of shape {a.shape}, "
                           f"expected (127 or more, {dim})")
        out[n] = a[FACE_FIRST:FACE_FIRST + FACE_COUNT]
    return out


def read_agora(path, df=None) -> AgoraPeople:
    """Read one AGORA ``*_withjv.pkl`` into per-person arrays (:class:`AgoraPeople`).

    Parameters
    ----------
    path : str or Path
        The pickle (**loading it runs code**; trusted files only).
    df : pandas.DataFrame, optional
        The already-loaded dataframe (``path`` is then only used in messages).
    """
    path = Path(path)
    if df is None:
        df = load_dataframe(path)
    frame = check_columns(df, path)
    rows = np.arange(len(df))
    valid_cells = [_as_list(v) for v in df["isValid"].tolist()]
    counts = np.array([len(c) for c in valid_cells], dtype=np.int64)
    row = np.repeat(rows, counts)
    person = np.concatenate([np.arange(c) for c in counts]) if len(counts) else np.zeros(0, dtype=np.int64)
    image = np.repeat(np.asarray(df["imgPath"].astype(str).tolist(), dtype=object), counts)

    def per_person(col):
        cells = [_as_list(v) for v in df[col].tolist()]
        lens = np.array([len(c) for c in cells], dtype=np.int64)
        if (lens != counts).any():
            k = int(np.flatnonzero(lens != counts)[0])
            raise HpeError(f"{path}: row {k}: column {col!r} has {lens[k]} entries, expected {counts[k]} "
                           "(one per person, as in isValid)")
        return cells

    valid = np.array(list(chain.from_iterable(valid_cells)), dtype=bool).reshape(-1)
    occ = np.array([np.nan if v is None else v for v in chain.from_iterable(per_person("occlusion"))],
                   dtype=np.float64).reshape(-1)
    if frame == "body":
        face3d = _joints(path, "cam_j3d", per_person("cam_j3d"), counts, rows, 3)
        cam_R = _stack(path, "camR", per_person("camR"), counts, (3, 3), rows)
        t_cells = [[np.asarray(t, dtype=np.float64).reshape(-1) for t in c] for c in per_person("camT")]
        cam_t = _stack(path, "camT", t_cells, counts, (3,), rows)
        K = _stack(path, "camK", per_person("camK"), counts, (3, 3), rows)
    else:
        face3d = _joints(path, "gt_joints_3d", per_person("gt_joints_3d"), counts, rows, 3)
        n = len(row)
        cam_R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        cam_t = np.zeros((n, 3))
        K = np.full((n, 3, 3), np.nan)  # rebuilt for the requested image size by the caller
    return AgoraPeople(path, row, person, image, valid, occ, face3d, cam_R, cam_t, K, frame, len(df))


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
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise HpeError(f"{people.source}: row {people.row[k]}: camK's principal point ({cx[k]:g}, {cy[k]:g}) "
                       f"is not at the centre of a {width}x{height} image nor of any image with that aspect "
                       "ratio; expected --image-size to match the images the dataframe was built for")
    S = np.zeros((n, 3, 3))
    S[:, 0, 0], S[:, 1, 1], S[:, 2, 2] = sx, sy, 1.0
    return S @ K, np.stack([sx, sy], axis=1)
