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

import gc
import tempfile
from pathlib import Path

import numpy as np
import orjson
import pyarrow as pa
import pyarrow.compute as pc

from ..errors import HpeError
from .layout import ANGLE_COLS, BBOX_COLS, arrow_to_numpy, landmark_count
from .writers import StreamWriter

CATEGORIES = [{"supercategory": "person", "id": 1, "name": "person"}]
#: written for a missing landmark (JSON has no NaN); AFLW2000-3D's own marker
MISSING_POINT = -1.0


def _finite(v, col, path, offset):
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise HpeError(
            f"{path}: row {offset + bad[0]}: expected a finite {col}, got {v[bad[0]]} "
            f"({bad.size} such rows in this batch)"
        )
    return v


def column_values(frame, col):
    """A column of a pandas DataFrame, pyarrow Table or RecordBatch as float64 (NaN for nulls)."""
    if hasattr(frame, "schema") and not hasattr(frame, "iloc"):
        return arrow_to_numpy(frame.column(col), np.float64)
    return frame[col].to_numpy(dtype=np.float64, na_value=np.nan)


def frame_column_names(frame):
    """Column names of a pandas frame or an Arrow table/batch."""
    return list(frame.schema.names) if hasattr(frame, "schema") and not hasattr(frame, "iloc") else list(frame.columns)


def string_column(frame, col) -> list:
    """Column ``col`` of a pandas frame or an Arrow table/batch as a list of ``str``."""
    if hasattr(frame, "schema") and not hasattr(frame, "iloc"):
        return [str(x) for x in frame.column(col).to_pylist()]
    return frame[col].astype(str).tolist()


def _image_codes(frame, path, offset: int):
    """``(codes, names)``: each row's index into ``names``, the batch's distinct ``image`` values in order of
    first appearance (hashed in C by pandas or Arrow; no Python string per row)."""
    if hasattr(frame, "iloc"):
        import pandas as pd

        col = frame["image"]
        if col.isna().any():
            bad = int(np.flatnonzero(col.isna().to_numpy())[0])
            raise HpeError(f"{path}: row {offset + bad}: expected an image name, got a missing value")
        codes, names = pd.factorize(col.astype(str), sort=False)
        return np.asarray(codes, dtype=np.int64), [str(x) for x in names]

    col = frame.column("image")
    if col.null_count:
        bad = int(np.flatnonzero(arrow_to_numpy(pc.is_null(col), np.uint8))[0])
        raise HpeError(f"{path}: row {offset + bad}: expected an image name, got a missing value")
    if not (pa.types.is_string(col.type) or pa.types.is_large_string(col.type)):
        col = pc.cast(col, pa.string())
    enc = pc.dictionary_encode(col)
    if isinstance(enc, pa.ChunkedArray):  # one dictionary for the whole batch
        enc = pc.dictionary_encode(col.combine_chunks()) if enc.num_chunks != 1 else enc.chunk(0)
    return arrow_to_numpy(enc.indices, np.int64), enc.dictionary.to_pylist()


#: rows serialised by one orjson call (bounds the Python objects alive at once)
CHUNK_ROWS = 4096


def annotations_text(frame, image_ids, first_id: int, *, path="<coco>", offset: int = 0):
    """The COCO ``annotations`` of a label batch as JSON text (bytes-like): the objects joined by commas, no
    brackets.

    Parameters
    ----------
    frame : pandas.DataFrame, pyarrow Table or RecordBatch
        ``bbox_x, bbox_y, bbox_w, bbox_h`` (pixels), ``pitch, yaw, roll``
        (degrees), optionally ``lm{i}_x, lm{i}_y`` (pixels); see :func:`write_coco`.
    image_ids : array of int, shape (n,)
        Each row's image id (:meth:`CocoWriter.image_ids`).
    first_id : int
        The annotation id of the first row (the others follow, +1 each).
    path, offset
        Output name and index of the batch's first row, for error messages.

    Notes
    -----
    The text of a row does not depend on how the table is cut into batches,
    so texts made apart (in worker processes) and joined with commas are the
    bytes :class:`CocoWriter` writes for the whole table. Each chunk of rows is
    one ``orjson.dumps`` over per-row dicts whose arrays are numpy row views:
    orjson formats the floats (shortest round-trip form) straight into its
    output, one pass over the text.
    """

    names = frame_column_names(frame)
    missing = [c for c in BBOX_COLS + ANGLE_COLS if c not in names]
    if missing:
        raise HpeError(f"{path}: expected columns {', '.join(missing)} in the label table")
    n_lm = landmark_count(names)
    image_ids = np.asarray(image_ids, dtype=np.int64)
    texts = []
    for lo in range(0, len(frame), CHUNK_ROWS):
        part = frame.iloc[lo : lo + CHUNK_ROWS] if hasattr(frame, "iloc") else frame.slice(lo, CHUNK_ROWS)
        n, off = len(part), offset + lo
        box = np.stack([_finite(column_values(part, c), c, path, off) for c in BBOX_COLS], axis=1)
        if (box[:, 2:] < 0).any():
            bad = int(np.flatnonzero((box[:, 2:] < 0).any(1))[0])
            raise HpeError(
                f"{path}: row {off + bad}: expected bbox_w, bbox_h >= 0, got {box[bad, 2]:g}, {box[bad, 3]:g}"
            )
        ang = np.stack([_finite(column_values(part, c), c, path, off) for c in ANGLE_COLS], axis=1)
        if n_lm:  # (n, 2, n_lm): face2d_pts = [[x0, x1, ...], [y0, y1, ...]]
            pts = np.empty((n, 2, n_lm))
            for i in range(n_lm):
                pts[:, 0, i] = column_values(part, f"lm{i}_x")
                pts[:, 1, i] = column_values(part, f"lm{i}_y")
            gone = ~np.isfinite(pts).all(axis=1)
            pts[np.repeat(gone[:, None, :], 2, axis=1)] = MISSING_POINT
        else:
            pts = [[]] * n  # orjson writes the same empty list for every row
        area = np.round(box[:, 2] * box[:, 3], 4).tolist()
        ids = image_ids[lo : lo + n].tolist()
        k0 = first_id + lo
        # one dict per row (about 1 us, a tenth of what formatting its floats costs), keys in coco_dict's order;
        # the cyclic garbage collector is paused meanwhile (these dicts hold no cycles, and its passes over
        # thousands of fresh containers would double the cost)
        paused = gc.isenabled()
        gc.disable()
        try:
            rows = [
                {
                    "image_id": i,
                    "id": k,
                    "category_id": 1,
                    "bbox": b,
                    "euler_angles": a,
                    "face2d_pts": p,
                    "area": ar,
                    "iscrowd": 0,
                    "segmentation": [],
                }
                for i, k, b, a, p, ar in zip(ids, range(k0, k0 + n), box, ang, pts, area)
            ]
        finally:
            if paused:
                gc.enable()
        if n:  # the list's brackets dropped without a copy
            texts.append(memoryview(orjson.dumps(rows, option=orjson.OPT_SERIALIZE_NUMPY))[1:-1])
    return texts[0] if len(texts) == 1 else b",".join(texts)


class CocoWriter(StreamWriter):
    """Write DirectMHP-style COCO JSON batch by batch, atomically (see :func:`write_coco`).

    ``annotations`` are written as they come; ``images`` (one entry per
    distinct ``image``, ids in order of first appearance) follow at the end,
    then ``categories``. The document equals :func:`coco_dict`'s, value for
    value (JSON key order aside).

    Each chunk of rows is serialised by one ``orjson.dumps`` call over a list
    of per-row dicts whose arrays are numpy views (orjson formats the floats,
    shortest round-trip form, straight into its output: one pass over the
    text, no splitting or re-joining). The bytes go to the file from a
    background thread (:class:`~hpe_cli.io.background.BackgroundFile`) while
    the next chunk is formatted.
    """

    separator = b","

    def __init__(
        self,
        path,
        overwrite: bool = False,
        *,
        width=None,
        height=None,
        info: dict | None = None,
        image_size_cols=("image_width", "image_height"),
    ):
        super().__init__(path, overwrite)
        self.width, self.height, self.info = width, height, dict(info or {})
        self.size_cols = tuple(image_size_cols)
        self.images: dict = {}  # name -> [id, width, height]

    def head(self) -> bytes:

        return b'{"info":' + orjson.dumps(self.info) + b',"licenses":[],"annotations":['

    def tail(self) -> bytes:

        images = [{"file_name": f, "height": h, "width": w, "id": i} for f, (i, w, h) in self.images.items()]
        return b'],"images":' + orjson.dumps(images) + b',"categories":' + orjson.dumps(CATEGORIES) + b"}"

    #: rows encoded at a time (bounds the text alive at once)
    CHUNK = CHUNK_ROWS

    def write(self, frame) -> None:
        """Append one batch (pandas DataFrame, pyarrow Table or RecordBatch) of label rows."""
        names = frame_column_names(frame)
        missing = [c for c in ["image"] + BBOX_COLS + ANGLE_COLS if c not in names]
        if missing:
            raise HpeError(f"{self.path}: expected columns {', '.join(missing)} in the label table")
        for lo in range(0, len(frame), self.CHUNK):
            part = frame.iloc[lo : lo + self.CHUNK] if hasattr(frame, "iloc") else frame.slice(lo, self.CHUNK)
            off = self.rows
            ids = self.image_ids(part, off)
            self.append_text(annotations_text(part, ids, off + 1, path=self.path, offset=off), len(part))

    def _sizes(self, frame, names, n: int, off: int) -> list:
        sizes = []
        for col, given in ((self.size_cols[0], self.width), (self.size_cols[1], self.height)):
            if col in names:
                v = column_values(frame, col)
                ok = np.isfinite(v) & (v > 0)
                if not ok.all():
                    bad = int(np.flatnonzero(~ok)[0])
                    raise HpeError(f"{self.path}: row {off + bad}: expected a positive {col}, got {v[bad]}")
                sizes.append(v.astype(np.int64))
            elif given is not None:
                sizes.append(np.full(n, int(given), dtype=np.int64))
            else:
                raise HpeError(f"{self.path}: expected an {col} column or an image size for the COCO 'images' entries")
        return sizes

    def image_ids(self, frame, offset: int = 0) -> np.ndarray:
        """Each row's image id (int64), the batch's new images remembered with their size.

        Ids are 1, 2, ... in order of first appearance over everything passed
        here; one image must keep one size (checked). ``offset`` is the index
        of the batch's first row in the whole table (for error messages).
        """
        codes, files = _image_codes(frame, self.path, offset)
        sizes = self._sizes(frame, frame_column_names(frame), len(frame), offset)
        first = np.unique(codes, return_index=True)[1]  # codes are 0, 1, ... in order of first appearance
        for col, v in zip(self.size_cols, sizes):
            differ = v != v[first][codes]
            if differ.any():
                bad = int(np.flatnonzero(differ)[0])
                a, b = sorted((int(v[first[codes[bad]]]), int(v[bad])))
                raise HpeError(
                    f"{self.path}: row {offset + bad}: expected one {col} per image "
                    f"({files[codes[bad]]}), got {a} and {b}"
                )
        images = self.images
        ids = np.empty(len(files), dtype=np.int64)
        for c, (f, w, h) in enumerate(zip(files, sizes[0][first].tolist(), sizes[1][first].tolist())):
            e = images.get(f)  # one lookup per distinct image of the batch, not per row
            if e is None:
                e = images[f] = [len(images) + 1, w, h]
            elif e[1] != w or e[2] != h:
                col = self.size_cols[0] if e[1] != w else self.size_cols[1]
                a, b = (e[1], w) if e[1] != w else (e[2], h)
                raise HpeError(
                    f"{self.path}: row {offset + int(first[c])}: expected one {col} per image ({f}), "
                    f"got {min(a, b):g} and {max(a, b):g}"
                )
            ids[c] = e[0]
        return ids[codes]


def coco_dict(
    frame,
    *,
    width=None,
    height=None,
    info: dict | None = None,
    path="<coco>",
    image_size_cols=("image_width", "image_height"),
) -> dict:
    """The COCO dictionary of a label table, as :func:`write_coco` writes it (small tables, tests)."""

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "c.json"
        write_coco(frame, out, width=width, height=height, info=info, image_size_cols=image_size_cols)
        doc = orjson.loads(out.read_bytes())
    return {k: doc[k] for k in ("info", "licenses", "images", "annotations", "categories")}


def write_coco(
    frame,
    path,
    overwrite: bool = False,
    *,
    width=None,
    height=None,
    info: dict | None = None,
    image_size_cols=("image_width", "image_height"),
    batch_size: int = 65536,
):
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
    with CocoWriter(path, overwrite, width=width, height=height, info=info, image_size_cols=image_size_cols) as w:
        for part in frame_parts(frame, batch_size):
            w.write(part)
    return Path(path)


def frame_parts(frame, batch_size):
    """A pandas frame or Arrow table/batch in parts of at most ``batch_size`` rows."""
    if hasattr(frame, "iloc"):
        for lo in range(0, len(frame), batch_size):
            yield frame.iloc[lo : lo + batch_size]
    elif hasattr(frame, "to_batches"):
        yield from frame.to_batches(max_chunksize=batch_size)
    elif hasattr(frame, "schema"):
        yield frame
    else:
        yield from frame
