"""COCO-style head-pose JSON, DirectMHP's schema (SPEC §7).

DirectMHP (``exps/AGORA/data_process_hpe.py``) trains from a COCO file whose
``images`` are ``{file_name, height, width, id}`` and whose ``annotations``
are ``{image_id, id, category_id: 1, bbox: [x, y, w, h], euler_angles: [pitch,
yaw, roll], face2d_pts: [[x...], [y...]], area, iscrowd: 0, segmentation: []}``
with a single ``person`` category. :func:`write_coco` writes that layout from
a label table, atomically, streaming: :class:`CocoWriter` takes the table in
batches and writes each batch's annotations at once (floats by ``orjson``),
so memory does not grow with the number of rows (only with the number of
distinct images, whose ids must be remembered).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError
from .layout import ANGLE_COLS, BBOX_COLS, landmark_count
from .writers import AtomicFile

CATEGORIES = [{"supercategory": "person", "id": 1, "name": "person"}]
#: written for a missing landmark (JSON has no NaN); AFLW2000-3D's own marker
MISSING_POINT = -1.0


def _finite(v, col, path, offset):
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise HpeError(f"{path}: row {offset + bad[0]}: expected a finite {col}, got {v[bad[0]]} "
                       f"({bad.size} such rows in this batch)")
    return v


def _column(frame, col):
    """A column of a pandas DataFrame, pyarrow Table or RecordBatch as float64 (NaN for nulls)."""
    if hasattr(frame, "schema") and not hasattr(frame, "iloc"):
        import pyarrow.compute as pc
        import pyarrow as pa

        c = frame.column(col)
        return np.asarray(pc.cast(c, pa.float64()).to_numpy(zero_copy_only=False), dtype=np.float64)
    return frame[col].to_numpy(dtype=np.float64, na_value=np.nan)


def _names(frame):
    return list(frame.schema.names) if hasattr(frame, "schema") and not hasattr(frame, "iloc") \
        else list(frame.columns)


def _strings(frame, col) -> list:
    if hasattr(frame, "schema") and not hasattr(frame, "iloc"):
        return [str(x) for x in frame.column(col).to_pylist()]
    return frame[col].astype(str).tolist()


def _rows_json(a) -> list:
    """orjson text of each row of a 2-D or 3-D float array, from one call (no Python float per value).

    Floats never contain brackets, so the rows of ``[[...],[...]]`` split at ``],[`` (``]],[[`` for 3-D).
    """
    import orjson

    if len(a) == 0:
        return []
    text = orjson.dumps(np.ascontiguousarray(a), option=orjson.OPT_SERIALIZE_NUMPY)
    if a.ndim == 2:
        return [b"[" + r + b"]" for r in text[2:-2].split(b"],[")]
    return [b"[[" + r + b"]]" for r in text[3:-3].split(b"]],[[")]


def _annotations(image_ids, off, box, ang, pts, area) -> list:
    """The JSON text of each annotation (DirectMHP's keys, in :func:`coco_dict`'s order)."""
    import orjson

    boxes, angles = _rows_json(box), _rows_json(ang)
    points = _rows_json(pts) if pts is not None else [b"[]"] * len(box)
    areas = orjson.dumps(area, option=orjson.OPT_SERIALIZE_NUMPY)[1:-1].split(b",") if len(area) else []
    return [b'{"image_id":%d,"id":%d,"category_id":1,"bbox":%s,"euler_angles":%s,"face2d_pts":%s,"area":%s,'
            b'"iscrowd":0,"segmentation":[]}' % (i, off + k + 1, b, a, p, ar)
            for k, (i, b, a, p, ar) in enumerate(zip(image_ids, boxes, angles, points, areas))]


class CocoWriter:
    """Write DirectMHP-style COCO JSON batch by batch, atomically (see :func:`write_coco`).

    ``annotations`` are written as they come; ``images`` (one entry per
    distinct ``image``, ids in order of first appearance) follow at the end,
    then ``categories``. The document equals :func:`coco_dict`'s, value for
    value (JSON key order aside).
    """

    def __init__(self, path, overwrite: bool = False, *, width=None, height=None, info: dict | None = None,
                 image_size_cols=("image_width", "image_height")):
        self._atomic = AtomicFile(path, overwrite)  # refuse an existing file before doing any work
        self.path = Path(path)
        self.width, self.height, self.info = width, height, dict(info or {})
        self.size_cols = tuple(image_size_cols)
        self.images: dict = {}  # name -> [id, width, height]
        self.rows = 0
        self._fh = None

    def __enter__(self):
        import orjson

        self._tmp = self._atomic.__enter__()
        self._fh = open(self._tmp, "wb")
        self._fh.write(b'{"info":' + orjson.dumps(self.info) + b',"licenses":[],"annotations":[')
        return self

    #: rows encoded at a time (bounds the Python objects alive at once)
    CHUNK = 8192

    def write(self, frame) -> None:
        """Append one batch (pandas DataFrame, pyarrow Table or RecordBatch) of label rows."""
        names = _names(frame)
        missing = [c for c in ["image"] + BBOX_COLS + ANGLE_COLS if c not in names]
        if missing:
            raise HpeError(f"{self.path}: expected columns {', '.join(missing)} in the label table")
        n = len(frame)
        for lo in range(0, n, self.CHUNK):
            part = frame.iloc[lo:lo + self.CHUNK] if hasattr(frame, "iloc") else frame.slice(lo, self.CHUNK)
            self._write(part, names)

    def _write(self, frame, names) -> None:
        n = len(frame)
        off = self.rows
        files = _strings(frame, "image")
        sizes = []
        for col, given in ((self.size_cols[0], self.width), (self.size_cols[1], self.height)):
            if col in names:
                v = _column(frame, col)
                ok = np.isfinite(v) & (v > 0)
                if not ok.all():
                    bad = int(np.flatnonzero(~ok)[0])
                    raise HpeError(f"{self.path}: row {off + bad}: expected a positive {col}, got {v[bad]}")
                sizes.append(v.astype(np.int64).tolist())
            elif given is not None:
                sizes.append([int(given)] * n)
            else:
                raise HpeError(f"{self.path}: expected an {col} column or an image size for the COCO "
                               "'images' entries")
        box = np.stack([_finite(_column(frame, c), c, self.path, off) for c in BBOX_COLS], axis=1)
        if (box[:, 2:] < 0).any():
            bad = int(np.flatnonzero((box[:, 2:] < 0).any(1))[0])
            raise HpeError(f"{self.path}: row {off + bad}: expected bbox_w, bbox_h >= 0, "
                           f"got {box[bad, 2]:g}, {box[bad, 3]:g}")
        ang = np.stack([_finite(_column(frame, c), c, self.path, off) for c in ANGLE_COLS], axis=1)
        n_lm = landmark_count(names)
        if n_lm:  # (n, 2, n_lm): face2d_pts = [[x0, x1, ...], [y0, y1, ...]], serialised by orjson from numpy
            pts = np.empty((n, 2, n_lm))
            for i in range(n_lm):
                pts[:, 0, i] = _column(frame, f"lm{i}_x")
                pts[:, 1, i] = _column(frame, f"lm{i}_y")
            gone = ~np.isfinite(pts).all(axis=1)
            pts[np.repeat(gone[:, None, :], 2, axis=1)] = MISSING_POINT
        else:
            pts = [[] for _ in range(n)]
        images = self.images
        image_ids = []
        for f, w, h in zip(files, sizes[0], sizes[1]):
            e = images.get(f)
            if e is None:
                e = images[f] = [len(images) + 1, w, h]
            elif e[1] != w or e[2] != h:
                col = self.size_cols[0] if e[1] != w else self.size_cols[1]
                a, b = (e[1], w) if e[1] != w else (e[2], h)
                raise HpeError(f"{self.path}: image {e[0] - 1}: expected one {col} per image, "
                               f"got {min(a, b):g} and {max(a, b):g}")
            image_ids.append(e[0])
        area = np.round(box[:, 2] * box[:, 3], 4)
        text = b",".join(_annotations(image_ids, off, box, ang, pts if n_lm else None, area))
        self._fh.write((b"," if self.rows else b"") + text)
        self.rows += n

    def __exit__(self, exc_type, exc, tb):
        import orjson

        try:
            if exc_type is None:
                images = [{"file_name": f, "height": h, "width": w, "id": i} for f, (i, w, h) in self.images.items()]
                self._fh.write(b'],"images":' + orjson.dumps(images) + b',"categories":' +
                               orjson.dumps(CATEGORIES) + b"}")
            self._fh.close()
        except BaseException:
            self._fh.close()
            self._atomic.__exit__(RuntimeError, None, None)
            raise
        return self._atomic.__exit__(exc_type, exc, tb)


def coco_dict(frame, *, width=None, height=None, info: dict | None = None, path="<coco>",
              image_size_cols=("image_width", "image_height")) -> dict:
    """The COCO dictionary of a label table, as :func:`write_coco` writes it (small tables, tests)."""
    import tempfile

    import orjson

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "c.json"
        write_coco(frame, out, width=width, height=height, info=info, image_size_cols=image_size_cols)
        doc = orjson.loads(out.read_bytes())
    return {k: doc[k] for k in ("info", "licenses", "images", "annotations", "categories")}


def write_coco(frame, path, overwrite: bool = False, *, width=None, height=None, info: dict | None = None,
               image_size_cols=("image_width", "image_height"), batch_size: int = 65536):
    """Write a label table as DirectMHP-style COCO JSON, atomically.

    Parameters
    ----------
    frame : pandas.DataFrame, pyarrow Table, or an iterable of either
        One row per head: ``image`` (path, used as ``file_name``), ``bbox_x,
        bbox_y, bbox_w, bbox_h`` (pixels, top-left corner and size),
        ``pitch, yaw, roll`` (degrees, written as ``euler_angles`` in that
        order and in whatever system the table holds -- DirectMHP's own files
        use the ``whenet`` system), optionally ``lm{i}_x, lm{i}_y`` (pixels;
        written as ``face2d_pts = [[x0, x1, ...], [y0, y1, ...]]``, a missing
        point as -1) and ``image_width, image_height``. An iterable of
        batches is written as it comes (memory flat in the number of rows).
    path : str or Path
        Output ``.json``; refused if it exists unless ``overwrite``.
    width, height : int, optional
        Image size for tables without the image-size columns.
    image_size_cols : (str, str)
        Names of the per-row image width and height columns, used when present.
    info : dict, optional
        Stored as the file's ``info`` object.

    Notes
    -----
    Image ids are 1, 2, ... in order of first appearance; annotation ids are
    1, 2, ... in row order; ``area`` is ``bbox_w * bbox_h``; ``category_id``
    is 1 (``person``). The output is strict JSON (no NaN). ``images`` follow
    ``annotations`` in the file (a streaming writer learns them as it goes);
    COCO readers look both up by key, so the order of keys is immaterial.
    """
    with CocoWriter(path, overwrite, width=width, height=height, info=info,
                    image_size_cols=image_size_cols) as w:
        for part in _parts(frame, batch_size):
            w.write(part)
    return Path(path)


def _parts(frame, batch_size):
    if hasattr(frame, "iloc"):
        for lo in range(0, len(frame), batch_size):
            yield frame.iloc[lo:lo + batch_size]
    elif hasattr(frame, "to_batches"):
        yield from frame.to_batches(max_chunksize=batch_size)
    elif hasattr(frame, "schema"):
        yield frame
    else:
        yield from frame
