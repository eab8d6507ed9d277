"""Pull validated label values (angles or matrices) out of a record batch.

Shared by every command that reads labels, so that "missing column",
"non-numeric" and "non-finite" mean the same thing everywhere.
"""

from __future__ import annotations

import numpy as np

from ..errors import HpeError
from ..rotation import soa
from ..rotation.check import rotation_screen_columns
from ..rotation.systems import get_system
from .layout import ANGLE_COLS, MATRIX_COLS
from .table_source import plain_numpy

#: angles beyond this many degrees are rejected (a unit or storage mistake, and float precision is gone)
MAX_ANGLE = 1e6


def numeric_column(batch, name):
    """Column as float64 plus a per-row reason ('' when usable)."""
    values, bad, reasons = numeric_values(batch, name)
    if reasons is None:
        reasons = np.full(len(values), "", dtype=object)
    return values, reasons


def numeric_values(batch, name):
    """Column ``name`` of ``batch`` as float64: ``(values, bad_mask, reasons_or_None)``.

    ``values`` is NaN where missing or non-numeric (infinities kept), ``bad_mask`` marks the rows that are not
    finite numbers, and ``reasons`` (object array, ``''`` for usable rows) is built only when a row is bad.

    Object arrays of reasons are slow to build and compare, and almost every
    row of a real table is fine, so the common path never touches them.
    """
    import pyarrow as pa  # lazy: start-up

    col = batch.column(batch.schema.get_field_index(name))
    numeric = (
        pa.types.is_integer(col.type)
        or pa.types.is_floating(col.type)
        or pa.types.is_boolean(col.type)
        or pa.types.is_decimal(col.type)
        or pa.types.is_null(col.type)
    )
    if numeric:
        if col.null_count == 0 and pa.types.is_float64(col.type):
            values = plain_numpy(col)  # float64 without nulls (the usual label column): no pyarrow.compute
        else:
            import pyarrow.compute as pc  # lazy: start-up (0.06 s)

            values = np.asarray(pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False), dtype=np.float64)
        bad = ~np.isfinite(values)
        if not bad.any():
            return values, bad, None
        null = (
            np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)
            if col.null_count
            else np.zeros(len(values), dtype=bool)
        )
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
    cols, ok, reasons = value_columns(batch, names)
    if radians and mode == "angles":
        # warns at the end of the run if they look like degrees
        from .units_watch import observe_radians  # lazy: start-up

        observe_radians(cols, ok)
        cols = [v * (180.0 / np.pi) for v in cols]
    elif mode == "angles":
        # warns at the end of the run if they look like radians
        from .units_watch import observe_degrees  # lazy: start-up

        observe_degrees(cols, ok)
    if mode == "matrix":
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


# ---------------------------------------------------------------- storage kinds
# (kept apart from the numeric extraction above: every storage kind is read here the same way)


def is_native(system, columns) -> bool:
    """True when ``columns`` hold the system's own declared value columns."""
    if system is None or (system.storage_kind == "angles" and not system.columns):
        return False
    cols = set(columns)
    return all(c in cols for c in system.value_columns)


def label_mode(columns, path="input", system=None) -> str:
    """The storage kind the label columns of a table hold.

    With ``system`` given, its own value columns (``system.value_columns``:
    e.g. ``rx, ry, rz`` for a rotation-vector system, ``pose_Rx..`` for
    OpenFace) are looked for first and their ``storage_kind`` is returned.
    Otherwise (or when they are absent) ``"angles"`` if ``pitch, yaw, roll``
    (degrees) are present, else ``"matrix"`` if ``r00..r22`` (the system's
    stored matrix) are, else an error naming what was expected.
    """

    system = get_system(system) if system is not None else None
    if is_native(system, columns):
        return system.storage_kind
    cols = set(columns)
    if all(c in cols for c in ANGLE_COLS):
        return "angles"
    if all(c in cols for c in MATRIX_COLS):
        return "matrix"
    own = ""
    if system is not None and (system.storage_kind != "angles" or system.columns):
        missing_own = [c for c in system.value_columns if c not in cols]
        own = (
            f"{system.name}'s {system.storage_kind} columns {','.join(system.value_columns)} "
            f"(missing {','.join(missing_own)}), or "
        )
    missing = [c for c in ANGLE_COLS if c not in cols]
    raise HpeError(
        f"{path}: missing column(s) {', '.join(missing)}: expected {own}angle columns pitch,yaw,roll "
        f"(degrees) or matrix columns r00..r22; found {', '.join(list(columns)[:12]) or 'no columns'}"
        f"{columns_map_hint(columns)}"
    )


def columns_map_hint(columns) -> str:
    """``; rename them with --columns-map pitch=Pitch,...`` when capitalised or decorated angle columns are
    present (``Pitch``, ``PITCH``, ``head_pitch``, ``yaw_deg``), else ``''``."""
    found = {}
    for role in ANGLE_COLS:
        hits = [c for c in columns if c != role and role in "".join(ch for ch in str(c).lower() if ch.isalpha())]
        exact = [c for c in hits if str(c).lower() == role]
        if len(exact) == 1 or len(hits) == 1:
            found[role] = (exact or hits)[0]
    if not found or set(found) | (set(columns) & set(ANGLE_COLS)) != set(ANGLE_COLS):  # the rename must complete them
        return ""
    pairs = ",".join(f"{r}={found[r]}" for r in ANGLE_COLS if r in found)
    return f"; rename them with --columns-map {pairs}"


def value_columns(batch, names):
    """``(columns, ok, reasons_or_None)`` for arbitrary numeric columns (first reason per row)."""
    cols, reasons = [], None
    ok = np.ones(batch.num_rows, dtype=bool)
    for name in names:
        v, bad, r = numeric_values(batch, name)
        cols.append(v)
        if r is not None:
            if reasons is None:
                reasons = np.full(batch.num_rows, "", dtype=object)
            first = bad & ok
            reasons[first] = r[first]
            ok &= ~bad
    return cols, ok, reasons


def _merge(ok, reasons, sub_ok_idx, sub_reasons):
    """Fold reasons found on the rows ``sub_ok_idx`` into the batch-wide ``ok``/``reasons``."""
    if sub_reasons is None:
        return ok, reasons
    bad = sub_reasons != ""
    if bad.any():
        if reasons is None:
            reasons = np.full(ok.size, "", dtype=object)
        idx = sub_ok_idx[bad]
        reasons[idx] = sub_reasons[bad]
        ok[idx] = False
    return ok, reasons


def angle_columns(batch, system, radians: bool = False):
    """The three angle columns of ``batch`` in degrees, role order: the system's own named angle columns when the
    table has them (converted from the system's declared units), else ``pitch, yaw, roll`` (``radians``: the
    user's claim that they are in radians). Returns ``(cols, ok, reasons)`` as :func:`value_columns`."""
    if is_native(system, batch.schema.names) and system.storage_kind == "angles":
        cols, ok, reasons = value_columns(batch, system.value_columns)
        if system.value_units == "radians":
            cols = [c * (180.0 / np.pi) for c in cols]
        return cols, ok, reasons
    return label_columns_fast(batch, "angles", radians)


def batch_rotations(batch, system, mode: str, radians: bool = False):
    """The stored matrices of one record batch, whatever the storage kind.

    Parameters
    ----------
    batch : pyarrow.RecordBatch
    system : RotationSystem or name
        The labels' system.
    mode : str
        What :func:`label_mode` returned for the table.
    radians : bool
        ``pitch, yaw, roll`` columns are in radians (hpe's own angle columns
        are degrees otherwise; a system's declared angle columns use its ``units``).

    Returns
    -------
    X : nested list (3x3) of 1-D float64 arrays of length n
        The system's stored matrix (structure of arrays, see
        :mod:`hpe_cli.rotation.soa`); unusable rows hold the identity.
    ok : ndarray of bool (n,)
    reasons : ndarray of object (n,) or None
        ``''`` for usable rows, else the first reason; None when all rows are usable.
    """

    system = get_system(system)
    n = batch.num_rows
    native = is_native(system, batch.schema.names)
    if mode == "angles":
        cols, ok, reasons = angle_columns(batch, system, radians)
        if not ok.all():
            cols = [np.where(ok, c, 0.0) for c in cols]
        X = system.soa_from_angles(*cols)
        return (
            [
                [np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)) if isinstance(v, float) else v for v in row]
                for row in X
            ],
            ok,
            reasons,
        )
    if mode == "matrix" and not (native and system.storage_kind == "matrix"):
        cols, ok, reasons = label_columns_fast(batch, "matrix")
        if not ok.all():
            eye = np.eye(3).ravel()
            cols = [np.where(ok, c, eye[k]) for k, c in enumerate(cols)]
        return [cols[0:3], cols[3:6], cols[6:9]], ok, reasons
    if mode != system.storage_kind or not native:
        raise HpeError(f"{mode} columns {', '.join(system.value_columns)} not found for system {system.name}")
    cols, ok, reasons = value_columns(batch, system.value_columns)
    if system.storage_kind in ("rotvec", "quaternion"):  # column kernels: no (n, 3, 3) stack on the hot path
        from ..rotation import storage as st  # lazy: start-up

        if system.storage_kind == "quaternion":
            c = cols if system.quaternion_order == "wxyz" else [cols[3], cols[0], cols[1], cols[2]]
            norm = np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2] + c[3] * c[3])
            bad = ok & ~(np.abs(norm - 1.0) <= 1e-3)
            if bad.any():
                if reasons is None:
                    reasons = np.full(n, "", dtype=object)
                reasons[bad] = "not a unit quaternion (norm differs from 1 by more than 1e-3)"
                ok = ok & ~bad
            if not ok.all():
                c = [np.where(ok, v, d) for v, d in zip(c, (1.0, 0.0, 0.0, 0.0))]
            X = st.quaternion_to_soa(*c)
        else:
            c = cols if ok.all() else [np.where(ok, v, 0.0) for v in cols]
            X = st.rotvec_to_soa(*c)
        return X, ok, reasons
    values = np.stack(cols, axis=-1)
    idx = np.flatnonzero(ok)
    R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    if idx.size:
        Rk, sub = system.values_to_matrix(values[idx])
        ok, reasons = _merge(ok, reasons, idx, sub)
        good = ok[idx]
        R[idx[good]] = Rk[good]
    return soa.from_array(R), ok, reasons


def rotation_value_columns(system, X, n: int) -> dict:
    """The system's own value columns (name -> 1-D array) of stored matrices ``X`` (nested list).

    Empty for angle systems without declared columns (hpe's ``pitch, yaw, roll``
    already hold them). Angle systems with declared columns get their angles
    in the system's units, the others their stored values.
    """

    if system.storage_kind == "angles":
        if not system.columns:
            return {}
        p1, _, _, _ = system.soa_to_angles(X)
        f = np.pi / 180.0 if system.value_units == "radians" else 1.0
        return {c: np.asarray(v * f, dtype=np.float64) for c, v in zip(system.value_columns, p1)}
    values = system.matrix_to_values(soa.to_array(X, n)) if n else np.zeros((0, len(system.value_columns)))
    return {c: np.ascontiguousarray(values[:, k]) for k, c in enumerate(system.value_columns)}


def label_values(batch, system, mode: str, radians: bool = False):
    """Label values for checks that look at angles or matrices as read (``hpe audit``).

    ``(n, 3)`` angles in degrees (role order) when the table holds angles
    (hpe's ``pitch, yaw, roll`` or the system's declared angle columns), else
    ``(n, 3, 3)`` stored matrices (any other storage kind is turned into its
    matrix). Unusable entries are NaN (for stored values: the whole row).
    """

    system = get_system(system)
    names = batch.schema.names
    if mode == "angles":
        native = is_native(system, names) and system.storage_kind == "angles"
        cols = system.value_columns if native else ANGLE_COLS
        values = np.stack([numeric_column(batch, c)[0] for c in cols], axis=-1)
        rad = (system.value_units == "radians") if native else radians
        from .units_watch import observe_degrees, observe_radians  # lazy: start-up

        if not rad:
            observe_degrees([values[:, 0], values[:, 1], values[:, 2]])
        elif not native:  # --radians (a system's own radian columns are its definition, not the user's claim)
            observe_radians([values[:, 0], values[:, 1], values[:, 2]])
        return np.rad2deg(values) if rad else values
    if mode == "matrix" and not (is_native(system, names) and system.storage_kind == "matrix"):
        return np.stack([numeric_column(batch, c)[0] for c in MATRIX_COLS], axis=-1).reshape(-1, 3, 3)
    cols = system.value_columns
    values = np.stack([numeric_column(batch, c)[0] for c in cols], axis=-1)
    R = np.full((len(values), 3, 3), np.nan)
    ok = np.isfinite(values).all(axis=1)
    if ok.any():
        Rk, reasons = system.values_to_matrix(values[ok]) if mode != "matrix" else (values[ok].reshape(-1, 3, 3), None)
        good = np.ones(len(Rk), dtype=bool) if reasons is None else reasons == ""
        if mode == "matrix":  # let audit's own checks see a non-rotation as it is
            good[:] = True
        idx = np.flatnonzero(ok)[good]
        R[idx] = Rk[good]
    return R
