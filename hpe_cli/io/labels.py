"""Pull validated label values (angles or matrices) out of a record batch.

Shared by every command that reads labels, so that "missing column",
"non-numeric" and "non-finite" mean the same thing everywhere.
"""
from __future__ import annotations

import numpy as np

from ..errors import HpeError
from .layout import ANGLE_COLS, MATRIX_COLS


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
    import pyarrow as pa
    import pyarrow.compute as pc

    col = batch.column(batch.schema.get_field_index(name))
    reasons = np.full(len(col), "", dtype=object)
    if pa.types.is_integer(col.type) or pa.types.is_floating(col.type) or pa.types.is_boolean(col.type) \
            or pa.types.is_decimal(col.type) or pa.types.is_null(col.type):
        values = pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False)
        values = np.asarray(values, dtype=np.float64)
        null = np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool) if col.null_count else None
    else:
        import pandas as pd

        raw = col.to_pandas()
        values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
        null = raw.isna().to_numpy()
        bad = np.isnan(values) & ~null
        reasons[bad] = f"non-numeric value in {name}"
    if null is not None and null.any():
        values = np.where(null, np.nan, values)
        reasons[null & (reasons == "")] = f"missing value in {name}"
    nonfinite = ~np.isfinite(values) & (reasons == "")
    reasons[nonfinite] = f"non-finite value in {name}"
    return values, reasons


def batch_label_columns(batch, mode: str, radians: bool = False):
    """Label columns of one batch as contiguous 1-D float64 arrays.

    Returns
    -------
    columns : list of ndarray
        ``[pitch, yaw, roll]`` in degrees, or the nine ``r00..r22`` entries.
    reasons : ndarray of object (n,)
        ``''`` for a usable row, else the first reason it is not (missing,
        non-numeric, non-finite; for matrices also "not a rotation").
    """
    names = ANGLE_COLS if mode == "angles" else MATRIX_COLS
    cols, reasons = [], np.full(batch.num_rows, "", dtype=object)
    for name in names:
        v, r = numeric_column(batch, name)
        cols.append(np.rad2deg(v) if (radians and mode == "angles") else v)
        if (r != "").any():
            reasons = np.where(reasons == "", r, reasons)
    if mode == "matrix":
        from ..rotation.check import rotation_reasons

        ok = reasons == ""
        R = np.stack(cols, axis=-1).reshape(-1, 3, 3)
        rr = rotation_reasons(R[ok] if not ok.all() else R)
        if (rr != "").any():
            sub = reasons[ok]
            reasons[ok] = np.where(sub == "", rr, sub)
    return cols, reasons


def batch_labels(batch, mode: str, radians: bool = False):
    """Label values of one batch.

    Returns
    -------
    values : ndarray
        ``(n, 3)`` angles in degrees (role order) or ``(n, 3, 3)`` matrices.
    reasons : ndarray of object (n,)
        ``''`` for a usable row, else the first reason it is not.
    """
    cols, reasons = batch_label_columns(batch, mode, radians)
    values = np.stack(cols, axis=-1)
    return (values if mode == "angles" else values.reshape(-1, 3, 3)), reasons
