"""The audited labels, batch by batch: the reader's rows, the label columns as float64, the checks of a batch."""

from __future__ import annotations

import numpy as np

from ...errors import HpeError
from ...io import ANGLE_COLS, MATRIX_COLS
from ...io.labels import label_values, numeric_values
from ...io.readers import LINE_COL
from ...io.table_source import plain_numpy
from ...io.units_watch import observe_degrees, observe_radians
from ...rotation.audit import audit_columns


def read_batches(src, mode, rejects=None):
    """``(batch, lines, unread)`` of ``src``; a row the reader sets aside fails the audit, naming its line.

    ``lines`` are the rows' file lines: the reader's line-number column, or for a source opened without it (a
    Parquet table, whose reader numbers its rows from 1) a ``range`` of the same numbers.

    A non-numeric label value is not such a row: it is read as NaN and
    counted as ``non_finite`` (``unread``: the reader's rows with such a value).
    With a rejects file (``rejects`` with a path), the other rows the reader
    sets aside go there instead.
    """
    label = {f"non-numeric value in {c}" for c in (ANGLE_COLS if mode == "angles" else MATRIX_COLS)}
    rejects_file = rejects
    first = 1  # a Parquet table read without line numbers: its rows are numbered from 1, as its reader does
    for batch, rejects in src.batches_with_rejects():
        unread = [r for r in rejects if r.reason in label]
        other = [r for r in rejects if r.reason not in label]
        if other and rejects_file is not None and rejects_file.path is not None:
            rejects_file.add_unreadable(other)
            rejects = unread
        if len(unread) < len(rejects):
            r = next(r for r in rejects if r.reason not in label)
            raise HpeError(
                f"{src.where(r.line)}: {r.reason} ({len(rejects) - len(unread)} unreadable rows in "
                "this block; use --rejects FILE to set them aside and audit the rest)"
            )
        if LINE_COL in batch.schema.names:
            lines = plain_numpy(batch.column(LINE_COL))  # Arrow's to_numpy imports pandas (0.2-0.4 s)
            batch = batch.drop_columns([LINE_COL])
        else:  # no column of numbers to make and read back (a range indexes, slices and measures alike)
            lines = range(first, first + batch.num_rows)
        first += batch.num_rows
        yield batch, lines, unread


def label_cols(batch, mode, radians):
    """Label columns of one batch as float64 arrays (degrees for angles); NaN where missing or non-numeric."""
    names = ANGLE_COLS if mode == "angles" else MATRIX_COLS
    cols = []
    for c in names:
        col = batch.column(batch.schema.get_field_index(c))
        if col.null_count == 0 and str(col.type) == "double":
            v = plain_numpy(col)  # what numeric_values gives, without its imports
        else:
            v, _, _ = numeric_values(batch, c)  # NaN where missing or non-numeric, inf kept
        cols.append(np.rad2deg(v) if (radians and mode == "angles") else v)
    if mode == "angles":  # warn at the end if the unit looks wrong
        if radians:
            observe_radians([np.deg2rad(c) for c in cols])
        else:
            observe_degrees(cols)
    return cols


def system_cols(batch, system, mode, radians, via_system):
    """Label columns to check and their mode: a system's own columns (any storage kind) are read through it."""
    if not via_system:
        return label_cols(batch, mode, radians), mode
    values = label_values(batch, system, mode, radians)
    return (
        [np.ascontiguousarray(c) for c in values.reshape(len(values), -1).T],
        "angles" if values.ndim == 2 else "matrix",
    )


def check_batch(cols, mode, system, near_tol_deg, primary=False):
    """The masks of :func:`hpe_cli.rotation.audit.audit_columns` (no ``lock_distance``: not reported; matrices'
    ``primary`` angles only when asked, for the plots)."""
    return audit_columns(cols, system, mode, near_tol_deg, lock_distance=False, primary=primary)


class SkipRejects:
    """The second pass skips the rows the first one set aside (already in the rejects file)."""

    path = "-"

    def add(self, *args, **kwargs):
        pass

    def add_unreadable(self, read_rejects):
        pass


#: the rejects stand-in of every second pass
SKIP_REJECTS = SkipRejects()
