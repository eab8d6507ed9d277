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
import pyarrow as pa

from ..errors import HpeError
from .fields import member_problem
from .mat import POSE_COLS, read_mat
from .mat_fields import check_fields

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
    m = check_fields(m, path)
    out = {"pts_2d": _points(m, "pts_2d", path), "pts_3d": _points(m, "pts_3d", path)}
    if out["pts_2d"] is None and out["pts_3d"] is None:
        raise HpeError(f"{path}: expected pts_2d and/or pts_3d in a 300W-LP landmark file")
    return out


def _check_members(path, names) -> None:
    """Refuse members with '..' or absolute names, and a name stored twice (its rows would be duplicated)."""

    seen = set()
    for n in names:
        why = member_problem(n)
        if why:
            raise HpeError(f"{path}: member {n!r}: refused: {why}")
        if n in seen:
            raise HpeError(
                f"{path}: member {n} appears twice in the archive (its rows would be duplicated); "
                "repack it with one copy"
            )
        seen.add(n)


class _Source:
    """The .mat entries of a root folder or a zip, and a way to open each (zip kept open while iterating)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.zip = self.path.is_file()
        self.rows, self.pts = [], {}
        if self.zip:
            try:
                with zipfile.ZipFile(self.path) as z:
                    names = [n for n in z.namelist() if not n.endswith("/")]
            except (zipfile.BadZipFile, OSError) as exc:
                raise HpeError(f"{self.path}: not a readable zip archive ({exc})") from None
            _check_members(self.path, names)
            for n in sorted(names):
                p = PurePosixPath(n)
                if p.suffix.lower() != ".mat":
                    continue
                parts = p.parts
                if len(parts) >= 3 and parts[-3] == "landmarks" and p.stem.endswith("_pts"):
                    self.pts[(parts[-2], p.stem[:-4])] = n
                    continue
                sub = _subset_of(parts[-2]) if len(parts) >= 2 else None
                if sub is not None:
                    self.rows.append((sub[0], sub[1], f"{parts[-2]}/{p.name}", n))
        else:
            for d in sorted(p for p in self.path.iterdir() if p.is_dir()):
                sub = _subset_of(d.name)
                if sub is None:
                    continue
                for f in sorted(d.glob("*.mat")):
                    self.rows.append((sub[0], sub[1], f"{d.name}/{f.name}", f))
            lm_root = self.path / "landmarks"
            if lm_root.is_dir():
                for s in SUBSETS:
                    for f in sorted((lm_root / s).glob("*_pts.mat")) if (lm_root / s).is_dir() else []:
                        self.pts[(s, f.stem[:-4])] = f
        if not self.rows:
            raise HpeError(f"{self.path}: no .mat files in {', '.join(SUBSETS)} or their _Flip folders")

    def read(self, rows, landmarks: bool):
        """(poses, pt2d, landmark dicts) of ``rows``."""
        z = zipfile.ZipFile(self.path) if self.zip else None
        try:
            poses, p2, lms = [], [], []
            for sub, flipped, rel, member in rows:
                if z is not None:
                    where = f"{self.path}:{member}"
                    try:
                        rec = read_mat(where, io.BytesIO(z.read(member)))
                    except (zipfile.BadZipFile, OSError, RuntimeError) as exc:
                        raise HpeError(f"{where}: cannot read the member ({exc})") from None
                else:
                    rec = read_mat(member)
                poses.append(rec["pose"])
                p2.append(rec["pt2d"])
                lm = None
                key = (sub, PurePosixPath(str(member)).stem)
                if landmarks and not flipped and key in self.pts:
                    src = self.pts[key]
                    lm = read_pts(f"{self.path}:{src}", io.BytesIO(z.read(src))) if z is not None else read_pts(src)
                lms.append(lm)
            return poses, p2, lms
        finally:
            if z is not None:
                z.close()


def _table(rows, poses, lms, path, pt2d_rows=None):
    import pandas as pd

    frame = pd.DataFrame(
        {
            "file": [r[2] for r in rows],
            "image": [str(PurePosixPath(r[2]).with_suffix(".jpg")) for r in rows],
            "subset": [r[0] for r in rows],
            "flipped": np.array([r[1] for r in rows], dtype=bool),
        }
    )
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
                p3[n, :, : l["pts_3d"].shape[1]] = l["pts_3d"]
        for i in range(68):
            for a, ax in enumerate("xyz"[:d]):
                extra[f"lm3d{i}_{ax}"] = p3[:, i, a]
    if pt2d_rows is not None and any(p is not None for p in pt2d_rows):
        L = max(p.shape[1] for p in pt2d_rows if p is not None)
        q = np.full((len(rows), 2, L), np.nan)
        for n, p in enumerate(pt2d_rows):
            if p is not None:
                q[n, :, : p.shape[1]] = p
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
    src = _Source(path)
    poses, p2, lms = src.read(src.rows, landmarks)
    return _table(src.rows, poses, lms, path, p2 if pt2d else None)


class W300LPStream:
    """300W-LP read ``chunk`` files at a time: ``schema``, ``num_rows``, ``system``, ``iter_batches()``.

    :func:`hpe_cli.io.readers.open_table` wraps it into a ``TableSource`` (line numbers, rejects protocol).
    """

    def __init__(self, src, schema, names, fields, chunk, landmarks, path):
        self.src, self.schema, self.names, self.fields = src, schema, names, fields
        self.chunk, self.landmarks, self.path = chunk, landmarks, path
        self.num_rows = len(src.rows)
        self.system = SYSTEM

    def iter_batches(self):

        rows_all = self.src.rows
        for start in range(0, len(rows_all), self.chunk):
            rows = rows_all[start : start + self.chunk]
            poses, _, lms = self.src.read(rows, self.landmarks)
            f = _table(rows, poses, lms, self.path)
            cols = [
                pa.array(f[n].to_numpy(), type=fd.type)
                if n in f.columns
                else pa.array(np.full(len(f), np.nan), type=fd.type)
                for n, fd in zip(self.names, self.fields)
            ]
            yield pa.RecordBatch.from_arrays(cols, schema=self.schema)


def open_w300lp(path, landmarks: bool = True, chunk: int = 2048) -> W300LPStream:
    """Stream 300W-LP (root or zip), ``chunk`` files at a time (memory flat in the number of files).

    The columns are those of :func:`read_w300lp` (without ``pt2d``); the
    landmark columns are present when the dataset has any landmark file.
    """

    src = _Source(path)
    dims3 = 0
    if landmarks and src.pts:
        s0 = next(iter(src.pts.values()))
        if src.zip:
            with zipfile.ZipFile(src.path) as z:
                first = read_pts(f"{src.path}:{s0}", io.BytesIO(z.read(s0)))
        else:
            first = read_pts(s0)
        dims3 = 0 if first["pts_3d"] is None else first["pts_3d"].shape[1]
    names = list(_table(src.rows[:0], [], [], path).columns)
    if landmarks and src.pts:
        names += [f"lm{i}_{a}" for i in range(68) for a in "xy"]
        names += [f"lm3d{i}_{a}" for i in range(68) for a in "xyz"[:dims3]]
    fields = [
        pa.field(n, pa.string())
        if n in ("file", "image", "subset", "identity")
        else pa.field(n, pa.bool_())
        if n == "flipped"
        else pa.field(n, pa.int64())
        if n == "k"
        else pa.field(n, pa.float64())
        for n in names
    ]
    schema = pa.schema(fields, metadata={b"hpe:system": SYSTEM.encode()})
    return W300LPStream(src, schema, names, fields, max(1, int(chunk)), landmarks, Path(path))
