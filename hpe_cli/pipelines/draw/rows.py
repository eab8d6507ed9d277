"""The rows ``hpe draw`` draws: reading them (canonical matrices, caption angles), where each face sits, how a
row is named in messages, and writing the pictures. Used by :mod:`.job` (label tables), :mod:`.errors`
(``hpe evaluate -o`` output), :mod:`.flagged` and :mod:`.consistency` (the audit pages' pictures) and by
:mod:`hpe_cli.pipelines.view`.
"""

from __future__ import annotations

import math
from pathlib import Path, PurePath
from typing import NamedTuple

import cv2
import numpy as np
import pandas as pd
import pyarrow as pa

from ...errors import HpeError
from ...io import batch_labels, batch_rotations
from ...io.images import IMAGE_COLUMNS
from ...io.readers import LINE_COL
from ...io.transaction import os_reason
from ...rotation import soa

#: 300W-LP/AFLW2000 Pose_Para: line length = this many Basel-Face-Model units times ``scale``.
#: The model is in micrometres and its origin is the centre of the head (the nose tip is
#: about 130 mm in front of it, the outer eye corners 43 mm to each side).
MAT_LENGTH_UNITS = 100_000.0
#: when a row gives no size: line length as a fraction of min(image width, height)
DEFAULT_LENGTH_FRACTION = 0.25
#: image file extensions OpenCV writes (any other name gets ``.png``)
WRITABLE = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"}


class Rows(NamedTuple):
    """A label table read whole for drawing (:func:`read_rows`)."""

    #: every column (pandas DataFrame)
    frame: object
    #: (N, 3, 3) canonical matrices, NaN where unusable
    A: np.ndarray
    #: (N, 3) pitch, yaw, roll in degrees in the labels' output system (captions), NaN where unusable
    angles: np.ndarray
    #: (N,) object: "" for a usable row, else why not
    reasons: np.ndarray
    #: (N,) the reader's line/row numbers (``__line__``), or None when the table was opened without them
    lines: np.ndarray | None


def read_rows(labels, radians=False, batches=None) -> Rows:
    """The whole table of ``labels`` (or the given ``batches`` of it) for drawing.

    Parameters
    ----------
    labels : LabelSource
        The opened table (:func:`hpe_cli.io.label_source.open_labels`): the labels are read in
        ``labels.system`` with ``labels.mode``; the caption angles are in ``labels.output_system`` (a dataset
        reader's labels, e.g. ``.mat`` Pose_Para, are read in the dataset's own system and converted).
    radians : bool
        Angle columns in radians (default degrees).
    batches : iterable of pyarrow.RecordBatch, optional
        Batches of ``labels.table`` to read instead of all of it.

    Returns
    -------
    Rows
    """
    src, mode, system, out_system = labels.table, labels.mode, labels.system, labels.output_system
    convert = out_system is not system and out_system.name != system.name
    batches = list(src.batches()) if batches is None else list(batches)
    lines = None
    if src.with_lines:
        lines = np.concatenate([b.column(LINE_COL).to_numpy() for b in batches]) if batches else np.zeros(0, int)
        batches = [b.drop_columns([LINE_COL]) for b in batches]
    schema = pa.schema([f for f in src.schema if f.name != LINE_COL], metadata=src.schema.metadata)
    table = pa.Table.from_batches(batches, schema=schema)
    if mode not in ("angles", "matrix") or (system.columns and all(c in src.columns for c in system.value_columns)):
        A, angles, reasons = _read_stored(batches, mode, radians, system)
        ok = reasons == ""
        if convert and ok.any():
            angles[ok] = out_system.to_angles(out_system.from_canonical(A[ok]))[0]
        return Rows(table.to_pandas(), A, angles, reasons, lines)
    values, reasons = [], []
    for b in batches:
        v, r = batch_labels(b, mode, radians)
        values.append(v)
        reasons.append(r)
    shape = (0, 3) if mode == "angles" else (0, 3, 3)
    values = np.concatenate(values) if values else np.zeros(shape)
    reasons = np.concatenate(reasons) if reasons else np.zeros(0, dtype=object)
    ok = reasons == ""
    A = np.full((len(values), 3, 3), np.nan)
    angles = np.full((len(values), 3), np.nan)
    if ok.any():
        if mode == "angles":
            A[ok] = system.to_canonical(system.from_angles(values[ok]))
            angles[ok] = values[ok]
        else:
            A[ok] = system.to_canonical(values[ok])
            angles[ok] = system.to_angles(values[ok])[0]
        if convert:
            angles[ok] = out_system.to_angles(out_system.from_canonical(A[ok]))[0]
    return Rows(table.to_pandas(), A, angles, reasons, lines)


def _read_stored(batches, mode, radians, system):
    """(canonical A, angles, reasons) of any storage kind (rotation vectors, quaternions, 6-D, named columns)."""
    As, angles, reasons = [], [], []
    for b in batches:
        X, ok, r = batch_rotations(b, system, mode, radians)
        R = soa.to_array(X, b.num_rows)
        a = np.full((b.num_rows, 3, 3), np.nan)
        g = np.full((b.num_rows, 3), np.nan)
        if ok.any():
            a[ok] = system.to_canonical(R[ok])
            g[ok] = system.to_angles(R[ok])[0]
        As.append(a)
        angles.append(g)
        reasons.append(r if r is not None else np.full(b.num_rows, "", dtype=object))
    if not As:
        return np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0, dtype=object)
    return np.concatenate(As), np.concatenate(angles), np.concatenate(reasons)


def numeric_values(frame, name):
    """Column ``name`` of ``frame`` as float64 (NaN where not a number; all NaN when there is no such column)."""
    if name not in frame.columns:
        return np.full(len(frame), np.nan)
    return pd.to_numeric(frame[name], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)


def face_placement(frame, pose_para: bool, length=None):
    """Per-row centre ``(N, 2)`` and length ``(N,)`` from the table, NaN where not given.

    Returns ``(centre, length, tdy_rows)``: ``tdy_rows`` marks rows whose centre
    came from ``tdx, tdy`` (so it may need flipping once the image height is known).
    """
    bx, by, bw, bh = (numeric_values(frame, c) for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h"))
    has_box = np.isfinite(bx) & np.isfinite(by) & np.isfinite(bw) & np.isfinite(bh)
    tdx, tdy = numeric_values(frame, "tdx"), numeric_values(frame, "tdy")
    has_td = ~has_box & np.isfinite(tdx) & np.isfinite(tdy)
    centre = np.full((len(frame), 2), np.nan)
    centre[has_box] = np.stack([bx + bw / 2, by + bh / 2], axis=1)[has_box]
    centre[has_td] = np.stack([tdx, tdy], axis=1)[has_td]
    L = np.full(len(frame), np.nan)
    L[has_box] = (bh / 2)[has_box]
    size = numeric_values(frame, "size")
    L = np.where(~has_box & np.isfinite(size), size, L)
    if pose_para:
        L = np.where(~has_box & ~np.isfinite(size), np.abs(numeric_values(frame, "scale")) * MAT_LENGTH_UNITS, L)
    if length is not None:
        L = np.full(len(frame), float(length))
    L = np.where(np.isfinite(L) & (L > 0), L, np.nan)
    return centre, L, has_td


def image_names(frame):
    """Image name per row (str), or None when the table names no images."""
    col = next((c for c in IMAGE_COLUMNS if c in frame.columns), None)
    if col is None:
        return None
    out = []
    for v in frame[col].tolist():
        if v is None or (isinstance(v, float) and math.isnan(v)):
            out.append(None)
            continue
        p = PurePath(str(v))
        out.append(str(p.with_suffix(".jpg")) if p.suffix.lower() == ".mat" else str(p))
    return out


def safe_relative(name, where):
    """``name`` as a path relative to the output folder (an absolute name keeps its file name only).

    Raises
    ------
    HpeError
        The name would leave the output folder (``..``) or is empty; ``where`` names the row.
    """
    rel = Path(name)
    if rel.is_absolute():
        rel = Path(rel.name)
    if ".." in rel.parts or not rel.parts:
        raise HpeError(f"{where}: image name {name!r} would be written outside the output folder")
    return rel


def row_namer(src, lines):
    """``f(i)`` naming 0-based row ``i`` of ``src`` as every message does (:meth:`TableSource.where
    <hpe_cli.io.table_source.TableSource.where>` of its line number): ``FILE: line N`` for text (1-based,
    header = line 1), the ``.mat`` file itself for a ``.mat`` folder, ``FILE: row N`` (1-based) otherwise."""
    if lines is None:
        return lambda i: f"{src.path}: row {int(i) + 1}"
    return lambda i: src.where(lines[i])


def row_numbers(src, lines, idx):
    """The numbers :func:`row_namer` names for 0-based rows ``idx`` (a rejects file's ``row`` column)."""
    idx = np.asarray(idx, dtype=np.int64)
    return idx + 1 if lines is None else np.asarray(lines, dtype=np.int64)[idx]


def write_image(img, staged, shown):
    """Encode ``img`` by ``shown``'s extension (PNG if unknown) into ``staged`` (a file in the staged folder)."""
    staged.parent.mkdir(parents=True, exist_ok=True)
    ext = shown.suffix.lower() if shown.suffix.lower() in WRITABLE else ".png"
    ok, buf = cv2.imencode(ext, img)
    if not ok:
        raise HpeError(f"{shown}: cannot encode the image as {ext}")
    try:
        staged.write_bytes(buf.tobytes())
    except OSError as exc:
        raise HpeError(f"{shown}: cannot write: {os_reason(exc)}") from None
