"""Pull validated label values (angles or matrices) out of a record batch.

Shared by every command that reads labels, so that "missing column",
"non-numeric" and "non-finite" mean the same thing everywhere.
"""
from __future__ import annotations

import numpy as np

from ..errors import HpeError
from .layout import ANGLE_COLS, MATRIX_COLS


#: angles beyond this many degrees are rejected (a unit or storage mistake, and float precision is gone)
MAX_ANGLE = 1e6


def label_mode(columns, path="input") -> str:
    """``"angles"`` if ``pitch, yaw, roll`` are present, else ``"matrix"`` if ``r00..r22`` are, else an error."""
    cols = set(columns)
    if all(c in cols for c in ANGLE_COLS):
        return "angles"
    if all(c in cols for c in MATRIX_COLS):
        return "matrix"
    missing = [c for c in ANGLE_COLS if c not in cols]
    raise HpeError(f"{path}: missing column(s) {', '.join(missing)}: expected angle columns pitch,yaw,roll "
                   f"(degrees) or matrix columns r00..r22; found {', '.join(list(columns)[:12]) or 'no columns'}")


def numeric_column(batch, name):
    """Column as float64 plus a per-row reason ('' when usable)."""
    values, bad, reasons = _numeric(batch, name)
    if reasons is None:
        reasons = np.full(len(values), "", dtype=object)
    return values, reasons


def _numeric(batch, name):
    """``(values, bad_mask, reasons_or_None)``; ``reasons`` is built only when a row is bad.

    Object arrays of reasons are slow to build and compare, and almost every
    row of a real table is fine, so the common path never touches them.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    col = batch.column(batch.schema.get_field_index(name))
    numeric = (pa.types.is_integer(col.type) or pa.types.is_floating(col.type) or pa.types.is_boolean(col.type)
               or pa.types.is_decimal(col.type) or pa.types.is_null(col.type))
    if numeric:
        if col.null_count == 0 and pa.types.is_float64(col.type):
            values = col.to_numpy()
        else:
            values = np.asarray(pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False), dtype=np.float64)
        bad = ~np.isfinite(values)
        if not bad.any():
            return values, bad, None
        null = np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool) if col.null_count else \
            np.zeros(len(values), dtype=bool)
        non_numeric = np.zeros(len(values), dtype=bool)
    else:
        import pandas as pd

        raw = col.to_pandas()
        values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
        null = raw.isna().to_numpy()
        non_numeric = np.isnan(values) & ~null
        bad = ~np.isfinite(values)
        if not bad.any():
            return values, bad, None
    values = np.where(null, np.nan, values)
    reasons = np.full(len(values), "", dtype=object)
    reasons[bad] = f"non-finite value in {name}"
    reasons[null] = f"missing value in {name}"
    reasons[non_numeric] = f"non-numeric value in {name}"
    return values, bad, reasons


def label_columns_fast(batch, mode: str, radians: bool = False):
    """Label columns of one batch as contiguous 1-D float64 arrays.

    Returns
    -------
    columns : list of ndarray
        ``[pitch, yaw, roll]`` in degrees, or the nine ``r00..r22`` entries.
    ok : ndarray of bool (n,)
        Usable rows.
    reasons : ndarray of object (n,) or None
        ``''`` for a usable row, else the first reason it is not (missing,
        non-numeric, non-finite; for matrices also "not a rotation"). None
        when every row is usable: the hot path then never builds or compares
        an object array.
    """
    names = ANGLE_COLS if mode == "angles" else MATRIX_COLS
    cols, reasons = [], None
    ok = np.ones(batch.num_rows, dtype=bool)
    for name in names:
        v, bad, r = _numeric(batch, name)
        cols.append(v * (180.0 / np.pi) if (radians and mode == "angles") else v)
        if r is not None:
            if reasons is None:
                reasons = np.full(batch.num_rows, "", dtype=object)
            first = bad & ok
            reasons[first] = r[first]
            ok &= ~bad
    if mode == "matrix":
        from ..rotation.check import rotation_screen_columns

        finite, ortho, proper = rotation_screen_columns(cols)
        not_rot = ok & ~(ortho & proper)
        if not_rot.any():
            if reasons is None:
                reasons = np.full(batch.num_rows, "", dtype=object)
            reasons[not_rot & ~finite] = "non-finite matrix entry"
            reasons[not_rot & finite & ~ortho] = "not a rotation: not orthonormal"
            reasons[not_rot & finite & ortho & ~proper] = "not a rotation: determinant is not +1 (a reflection)"
            ok &= ~not_rot
    else:
        huge = ok & ((np.abs(cols[0]) > MAX_ANGLE) | (np.abs(cols[1]) > MAX_ANGLE) | (np.abs(cols[2]) > MAX_ANGLE))
        if huge.any():
            if reasons is None:
                reasons = np.full(batch.num_rows, "", dtype=object)
            for name, c in zip(names, cols):
                first = huge & (np.abs(c) > MAX_ANGLE) & (reasons == "")
                reasons[first] = f"absurd angle in {name}: |value| > {MAX_ANGLE:g} degrees"
            ok &= ~huge
    return cols, ok, reasons


def batch_labels(batch, mode: str, radians: bool = False):
    """Label values of one batch.

    Returns
    -------
    values : ndarray
        ``(n, 3)`` angles in degrees (role order) or ``(n, 3, 3)`` matrices.
    reasons : ndarray of object (n,)
        ``''`` for a usable row, else the first reason it is not.
    """
    cols, _, reasons = label_columns_fast(batch, mode, radians)
    if reasons is None:
        reasons = np.full(batch.num_rows, "", dtype=object)
    values = np.stack(cols, axis=-1)
    return (values if mode == "angles" else values.reshape(-1, 3, 3)), reasons
