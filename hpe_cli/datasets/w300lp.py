"""300W-LP as shipped: the root folder or ``300W-LP.zip``, with its landmark files.

Layout (Zhu et al., 3DDFA; the archive unpacks to ``300W_LP/``)::

    300W_LP/{AFW,HELEN,IBUG,LFPW}/NAME_k.{jpg,mat}        k = 0, 1, ... rotated copies of one face
    300W_LP/{AFW,HELEN,IBUG,LFPW}_Flip/NAME_k.{jpg,mat}   the same, mirrored
    300W_LP/landmarks/{AFW,HELEN,IBUG,LFPW}/NAME_k_pts.mat

``NAME`` (e.g. ``IBUG_image_008_1``) is one face of the source dataset and
``k`` indexes its synthesised out-of-plane rotations, so ``identity = NAME``
is the group that must stay within one split. Each ``.mat`` holds
``Pose_Para`` (pitch, yaw, roll in radians -- always the ``300w_lp`` system --
then tdx, tdy, tdz, scale) and ``pt2d``.

**``pt2d`` of a rotated copy comes from the original image** (3DDFA issue
#192): for ``k > 0`` it does not match the rotated face. The landmark files
``landmarks/<subset>/NAME_k_pts.mat`` hold the points of the copy itself:
``pts_2d`` (68 x 2, image x, y) and ``pts_3d`` (68 x 2: the 3-D-fitted
landmarks projected into the image), the keys face-alignment code reads with
``loadmat(...)['pts_2d']``. When they are present they become the
``lm{i}_x, lm{i}_y`` columns (``pts_2d``) and ``lm3d{i}_x, lm3d{i}_y``
(``pts_3d``); the main file's ``pt2d`` is kept as ``pt2d{i}_x, pt2d{i}_y``
only with ``pt2d=True``. The landmark folder has no ``_Flip`` subsets, so
mirrored rows have no landmark columns (NaN).
"""
from __future__ import annotations

import io
import re
import zipfile
from pathlib import Path, PurePosixPath

import numpy as np

from ..errors import HpeError
from .mat import POSE_COLS, read_mat

SUBSETS = ("AFW", "HELEN", "IBUG", "LFPW")
SYSTEM = "300w_lp"
_NAME_K = re.compile(r"^(?P<name>.+)_(?P<k>\d+)$")


def split_name(stem: str):
    """``"IBUG_image_008_1_0"`` -> ``("IBUG_image_008_1", 0)``; ``(stem, -1)`` when there is no ``_k``."""
    m = _NAME_K.match(stem)
    if m is None:
        return stem, -1
    return m.group("name"), int(m.group("k"))


def _subset_of(folder: str):
    """``"AFW_Flip"`` -> ``("AFW", True)``; None for other folders."""
    flipped = folder.endswith("_Flip")
    base = folder[:-5] if flipped else folder
    return (base, flipped) if base in SUBSETS else None


def is_w300lp_root(path) -> bool:
    """A folder holding at least one of ``AFW, HELEN, IBUG, LFPW`` (or ``_Flip``) with ``.mat`` files."""
    path = Path(path)
    if not path.is_dir():
        return False
    for s in SUBSETS:
        for d in (path / s, path / f"{s}_Flip"):
            if d.is_dir() and next(d.glob("*.mat"), None) is not None:
                return True
    return False


def is_w300lp_zip(path) -> bool:
    path = Path(path)
    if not (path.is_file() and path.suffix.lower() == ".zip"):
        return False
    try:
        with zipfile.ZipFile(path) as z:
            return any(n.lower().endswith(".mat") for n in z.namelist())
    except (zipfile.BadZipFile, OSError):
        return False


def _points(m, key, path):
    v = m.get(key)
    if v is None:
        return None
    v = np.asarray(v, dtype=np.float64)
    if v.ndim != 2 or 68 not in v.shape or not ({2, 3} & set(v.shape)):
        raise HpeError(f"{path}: {key} has shape {v.shape}, expected (68, 2) or (68, 3)")
    return v if v.shape[0] == 68 else v.T  # (68, d)


def read_pts(path, fileobj=None) -> dict:
    """Read a ``NAME_k_pts.mat`` landmark file: ``pts_2d`` and ``pts_3d`` as (68, d) arrays (or None)."""
    import scipy.io

    try:
        m = scipy.io.loadmat(fileobj if fileobj is not None else path, variable_names=["pts_2d", "pts_3d"])
    except Exception as exc:  # scipy raises many types for corrupt files
        raise HpeError(f"{path}: not a readable MATLAB .mat file ({' '.join(str(exc).split())[:160]})") from None
    out = {"pts_2d": _points(m, "pts_2d", path), "pts_3d": _points(m, "pts_3d", path)}
    if out["pts_2d"] is None and out["pts_3d"] is None:
        raise HpeError(f"{path}: expected pts_2d and/or pts_3d in a 300W-LP landmark file")
    return out


def _entries_from_root(root: Path):
    """(subset, flipped, relative name, opener) for every .mat of a root folder, sorted."""
    out = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        sub = _subset_of(d.name)
        if sub is None:
            continue
        for f in sorted(d.glob("*.mat")):
            out.append((sub[0], sub[1], f"{d.name}/{f.name}", f))
    if not out:
        raise HpeError(f"{root}: no .mat files in {', '.join(SUBSETS)} or their _Flip folders")
    return out


def _table(rows, poses, lms, path, pt2d_rows=None):
    import pandas as pd

    frame = pd.DataFrame({
        "file": [r[2] for r in rows],
        "image": [str(PurePosixPath(r[2]).with_suffix(".jpg")) for r in rows],
        "subset": [r[0] for r in rows],
        "flipped": np.array([r[1] for r in rows], dtype=bool),
    })
    ident = [split_name(PurePosixPath(r[2]).stem) for r in rows]
    frame["identity"] = [i[0] for i in ident]
    frame["k"] = np.array([i[1] for i in ident], dtype=np.int64)
    P = np.stack(poses) if poses else np.zeros((0, 7))
    for i, c in enumerate(POSE_COLS):
        frame[c] = P[:, i]
    extra = {}
    have2 = [l for l in lms if l is not None and l["pts_2d"] is not None]
    if have2:
        xy = np.full((len(rows), 68, 2), np.nan)
        for n, l in enumerate(lms):
            if l is not None and l["pts_2d"] is not None:
                xy[n] = l["pts_2d"][:, :2]
        for i in range(68):
            extra[f"lm{i}_x"], extra[f"lm{i}_y"] = xy[:, i, 0], xy[:, i, 1]
    have3 = [l for l in lms if l is not None and l["pts_3d"] is not None]
    if have3:
        d = max(l["pts_3d"].shape[1] for l in have3)
        p3 = np.full((len(rows), 68, d), np.nan)
        for n, l in enumerate(lms):
            if l is not None and l["pts_3d"] is not None:
                p3[n, :, :l["pts_3d"].shape[1]] = l["pts_3d"]
        for i in range(68):
            for a, ax in enumerate("xyz"[:d]):
                extra[f"lm3d{i}_{ax}"] = p3[:, i, a]
    if pt2d_rows is not None and any(p is not None for p in pt2d_rows):
        L = max(p.shape[1] for p in pt2d_rows if p is not None)
        q = np.full((len(rows), 2, L), np.nan)
        for n, p in enumerate(pt2d_rows):
            if p is not None:
                q[n, :, :p.shape[1]] = p
        for i in range(L):
            extra[f"pt2d{i}_x"], extra[f"pt2d{i}_y"] = q[:, 0, i], q[:, 1, i]
    if extra:
        frame = pd.concat([frame, pd.DataFrame(extra)], axis=1)
    frame.attrs["system"] = SYSTEM
    return frame


def read_w300lp(path, landmarks: bool = True, pt2d: bool = False):
    """Read 300W-LP from its root folder or ``300W-LP.zip`` (members read in memory, never extracted).

    Returns
    -------
    pandas.DataFrame
        ``file`` (``<subset folder>/NAME_k.mat``), ``image`` (same with
        ``.jpg``), ``subset`` (AFW, HELEN, IBUG, LFPW), ``flipped`` (bool),
        ``identity`` (``NAME``), ``k`` (int, -1 if the name has no ``_k``),
        ``pitch, yaw, roll`` (degrees, ``300w_lp`` system), ``tdx, tdy, tdz,
        scale``; with ``landmarks`` and a ``landmarks/`` folder, ``lm{i}_x/y``
        (``pts_2d``) and ``lm3d{i}_x/y`` (``pts_3d``); with ``pt2d`` the main
        file's ``pt2d`` as ``pt2d{i}_x/y`` (from the original image, see the
        module notes). ``attrs["system"] == "300w_lp"``.
    """
    path = Path(path)
    if path.is_file():
        return _read_zip(path, landmarks, pt2d)
    rows = _entries_from_root(path)
    poses, lms, p2 = [], [], []
    lm_root = path / "landmarks"
    for sub, flipped, rel, f in rows:
        rec = read_mat(f)
        poses.append(rec["pose"])
        p2.append(rec["pt2d"])
        lm = None
        if landmarks and not flipped:
            cand = lm_root / sub / f"{f.stem}_pts.mat"
            if cand.is_file():
                lm = read_pts(cand)
        lms.append(lm)
    return _table(rows, poses, lms, path, p2 if pt2d else None)


def _read_zip(path: Path, landmarks: bool, pt2d: bool):
    try:
        z = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise HpeError(f"{path}: not a readable zip archive ({exc})") from None
    with z:
        names = [n for n in z.namelist() if not n.endswith("/")]
        pts = {}
        rows = []
        for n in sorted(names):
            p = PurePosixPath(n)
            if p.suffix.lower() != ".mat":
                continue
            parts = p.parts
            if len(parts) >= 3 and parts[-3] == "landmarks" and p.stem.endswith("_pts"):
                pts[(parts[-2], p.stem[:-4])] = n
                continue
            if len(parts) < 2:
                continue
            sub = _subset_of(parts[-2])
            if sub is None:
                continue
            rows.append((sub[0], sub[1], f"{parts[-2]}/{p.name}", n))
        if not rows:
            raise HpeError(f"{path}: no .mat members in {', '.join(SUBSETS)} or their _Flip folders")
        poses, lms, p2 = [], [], []
        for sub, flipped, rel, member in rows:
            where = f"{path}:{member}"
            try:
                data = z.read(member)
            except (zipfile.BadZipFile, OSError, RuntimeError) as exc:
                raise HpeError(f"{where}: cannot read the member ({exc})") from None
            rec = read_mat(where, io.BytesIO(data))
            poses.append(rec["pose"])
            p2.append(rec["pt2d"])
            lm = None
            key = (sub, PurePosixPath(member).stem)
            if landmarks and not flipped and key in pts:
                lm = read_pts(f"{path}:{pts[key]}", io.BytesIO(z.read(pts[key])))
            lms.append(lm)
    return _table(rows, poses, lms, path, p2 if pt2d else None)
