"""``hpe infer DATA``: a data table read for the search -- its angles, where its rotations are (matrix columns,
stored values or 3-D landmarks), the unusable rows set aside as rejects -- and the search itself."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pyarrow as pa

from ...datasets.mat import read_mat_dir
from ...errors import HpeError
from ...geometry.template import POOR_FIT_RMSE, fit_template, to_canonical_points
from ...io import MATRIX_COLS, Rejects, open_table, read_table
from ...io.readers import LINE_COL
from ...io.table_source import row_name
from ...rotation import infer as inf
from ...rotation import storage as st
from .options import ROLE_NAMES, InferOptions

#: stored rotation columns infer reads from a data table when it has no r00..r22 (see --rotations)
STORED_DEFAULTS = (("rotvec", ("rx", "ry", "rz")), ("quaternion-wxyz", ("qw", "qx", "qy", "qz")))


def matrix_columns(spec, columns) -> list | None:
    """The 9 matrix columns: ``spec`` (already 9 names) or ``r00..r22`` when the table has them, else None."""
    if spec is not None:
        return list(spec)
    return MATRIX_COLS if set(MATRIX_COLS) <= set(columns) else None


def stored_rotations(spec, columns):
    """``(kind, columns)`` of stored rotation values: ``spec``, else ``rx,ry,rz`` / ``qw,qx,qy,qz`` if present."""
    if spec is not None:
        return spec
    for kind, cols in STORED_DEFAULTS:
        if set(cols) <= set(columns):
            return kind, list(cols)
    return None


def stored_to_matrices(kind, values):
    """Matrices from stored values (rows that are not finite stay NaN, and are skipped by the search)."""
    R = np.full((len(values), 3, 3), np.nan)
    ok = np.isfinite(values).all(axis=1)
    v = values[ok]
    if kind == "rotvec":
        R[ok] = st.rotvec_to_matrix(v)
    elif kind.startswith("quaternion"):
        R[ok] = st.quaternion_to_matrix(v, order=kind.split("-")[1])
    else:
        R[ok] = st.sixd_to_matrix(v)
    return R


def read_data(path, units):
    """``(frame, units)``: a ``.mat`` file or folder (with its landmarks; angles in degrees) or a table."""
    p = Path(path)
    if p.is_dir() or p.suffix.lower() == ".mat":
        if units == "rad":
            raise HpeError(f"{path}: --radians does not apply to .mat files (Pose_Para is read in degrees)")
        return read_mat_dir(p, landmarks=True), "deg"
    return read_table(p), units or "deg"


#: table kinds whose values are typed (no unparseable row to set aside) or one-record files
_NOT_TEXT = (".parquet", ".pq", ".arrow", ".feather", ".mat")


def read_text_table_with_rejects(path):
    """A text table with the rows the reader cannot parse set aside: ``(frame, file line of each row, [Reject])``
    (``--rejects``: such a row is a reject, as in every command, not the end of the run)."""
    src = open_table(path, with_lines=True)
    batches, read_rejects = [], []
    for b, rr in src.batches_with_rejects():
        batches.append(b)
        read_rejects += rr
    frame = pa.Table.from_batches(batches, schema=src.schema).to_pandas()
    lines = frame.pop(LINE_COL).to_numpy()
    return frame, lines, read_rejects


def numeric(frame, cols, path):
    """The columns ``cols`` of ``frame`` as a float64 array (N, len(cols)); an error naming ``path`` when one is
    missing or holds no numbers."""
    missing = [c for c in cols if c not in frame.columns]
    if missing:
        raise HpeError(
            f"{path}: missing column(s) {', '.join(missing[:6])}{' ...' if len(missing) > 6 else ''}; "
            f"expected {', '.join(cols[:3])}{' ...' if len(cols) > 3 else ''}"
        )
    try:
        return frame[cols].to_numpy(dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise HpeError(f"{path}: columns {', '.join(cols[:3])}...: expected numbers ({exc})") from None


@dataclass(frozen=True)
class DataTable:
    """A data table read for the search.

    Attributes
    ----------
    path : str or Path
        The input, for messages and rejects.
    frame : pandas.DataFrame
        Its rows (those still in the search).
    pyr : ndarray, shape (N, 3)
        The angles in role order (pitch, yaw, roll), degrees.
    roles : list of str
        The roles of the angle columns, in storage order.
    units : {"deg", "rad"}
        The units the angle columns were read in.
    mcols : list of str or None
        The 9 matrix columns (None: stored values or landmarks).
    stored : (kind, columns) or None
        Stored rotation values instead of a matrix.
    landmarks3d : str or None
        The prefix of 68 3-D landmark columns (the landmark ranking instead of the table search).
    lines : ndarray or None
        Each row's file line when rows were set aside while reading.
    read_rejects : tuple
        The rows the reader could not parse (:class:`~hpe_cli.io.readers.Reject`).
    """

    path: object
    frame: object
    pyr: np.ndarray
    roles: list
    units: str
    mcols: list | None
    stored: tuple | None
    landmarks3d: str | None
    lines: np.ndarray | None = None
    read_rejects: tuple = ()


def read_data_table(data, opts: InferOptions) -> DataTable:
    """Read ``data``: its angles (to degrees, role order) and where its rotations are.

    With ``opts.rejects`` a text table's unparseable rows are kept aside (they become rejects); the rotations are
    ``opts.matrix`` (or ``r00..r22``), else stored values (``opts.rotations``, or ``rx,ry,rz`` / ``qw,qx,qy,qz``),
    else the 3-D landmarks (``opts.landmarks3d``, or ``lm3d`` when present).

    Raises
    ------
    HpeError
        Missing angle columns, or no rotation of any kind.
    """
    lines, read_rejects, units = None, [], opts.units
    dpath = Path(str(data))
    if opts.rejects is not None and dpath.is_file() and dpath.suffix.lower() not in _NOT_TEXT:
        frame_df, lines, read_rejects = read_text_table_with_rejects(data)
        units = units or "deg"
    else:
        frame_df, units = read_data(data, units)
    roles, cols = opts.angle_columns or (list(ROLE_NAMES), list(ROLE_NAMES))
    vals = numeric(frame_df, list(cols), data)
    if units == "rad":
        vals = np.rad2deg(vals)
    pyr = np.empty_like(vals)
    pyr[:, [ROLE_NAMES.index(r) for r in roles]] = vals
    landmarks3d = opts.landmarks3d
    mcols = matrix_columns(opts.matrix, frame_df.columns) if landmarks3d is None else None
    stored = None
    if landmarks3d is None and (opts.rotations is not None or mcols is None):
        stored = stored_rotations(opts.rotations, frame_df.columns)
    if landmarks3d is None and mcols is None and stored is None:
        if "lm3d0_x" not in frame_df.columns:
            raise HpeError(
                f"{data}: found neither matrix columns r00..r22, stored rotations (rx,ry,rz or "
                "qw,qx,qy,qz) nor 3-D landmarks lm3d0_x..; use --matrix, --rotations or --landmarks3d"
            )
        landmarks3d = "lm3d"
    return DataTable(data, frame_df, pyr, roles, units, mcols, stored, landmarks3d, lines, tuple(read_rejects))


def _landmark_columns(prefix: str) -> list:
    """The 68 3-D landmark columns ``PREFIX{i}_x, _y, _z``."""
    return [f"{prefix}{i}_{a}" for i in range(68) for a in "xyz"]


def set_aside_unusable(table: DataTable, opts: InferOptions) -> DataTable:
    """The table without the rows whose angles or rotation values are missing or not finite.

    Such rows cannot take part in the search: they go to ``--rejects`` with their reason (named ``FILE: line N``
    / ``row N`` / the ``.mat`` file), and without a rejects file (or with ``--strict``) they are an error, as in
    every command that reads rows.
    """
    frame_df, data = table.frame, table.path
    if table.stored is not None:
        cols = list(table.stored[1])
    elif table.mcols is not None:
        cols = list(table.mcols)
    else:
        cols = _landmark_columns(table.landmarks3d)
    cols = [c for c in cols if c in frame_df.columns]
    values = numeric(frame_df, cols, data) if cols else np.zeros((len(frame_df), 0))
    bad_angles = ~np.isfinite(table.pyr).all(axis=1)
    bad = bad_angles | ~np.isfinite(values).all(axis=1)
    if not bad.any() and not table.read_rejects:
        return table
    idx = np.flatnonzero(bad)
    reasons = np.where(
        bad_angles[idx],
        "angle not finite (missing, NaN or infinite)",
        "rotation value not finite (missing, NaN or infinite)",
    ).astype(object)
    rej = Rejects(opts.rejects, opts.overwrite, strict=opts.strict, source=str(data))
    if table.read_rejects:
        read_lines = np.array([r.line for r in table.read_rejects], dtype=np.int64)
        rej.add(
            {"input": np.full(len(read_lines), str(data), dtype=object), "row": read_lines},
            [r.reason for r in table.read_rejects],
            where=row_name(str(data), int(read_lines[0])),
        )
    if len(idx):
        rows = _row_names(table, idx)
        rej.add(
            {"input": np.full(len(idx), str(data), dtype=object), "row": rows},
            reasons,
            where=row_name(str(data), rows[0]),
        )
    rej.finish()
    keep = ~bad
    return replace(table, frame=frame_df[keep].reset_index(drop=True), pyr=table.pyr[keep])


def _row_names(table: DataTable, idx) -> np.ndarray:
    """How the rejects name the rows ``idx``: a one-record file by its name, a text table's row by its file line
    (header = line 1), another table's by its 1-based row."""
    p = Path(str(table.path))
    if "file" in table.frame.columns and (p.is_dir() or p.suffix.lower() == ".mat"):
        return table.frame["file"].astype(str).to_numpy()[idx]  # one-record files name themselves
    text = p.suffix.lower() not in (".parquet", ".pq", ".arrow", ".feather")
    rows = idx + (2 if text else 1)  # text: file line (header = line 1); tables: 1-based row
    if table.lines is not None:  # rows were set aside while reading: each keeps its own file line
        rows = np.asarray(table.lines)[idx]
    return rows


def infer_data(table: DataTable, opts: InferOptions) -> dict:
    """The table search (matrix or stored rotation columns) or the landmark ranking (3-D landmark columns)."""
    if table.landmarks3d is not None:
        return _infer_landmarks(table, opts)
    frame_df, data, stored = table.frame, table.path, table.stored
    if stored is not None:
        R = stored_to_matrices(stored[0], numeric(frame_df, stored[1], data))
    else:
        R = numeric(frame_df, table.mcols, data).reshape(-1, 3, 3)
    rep = inf.infer_table(
        table.pyr,
        R,
        roles=table.roles,
        units="degrees" if table.units == "deg" else "radians",
        tol=opts.tol or inf.DATA_TOL,
        source=str(data),
        name=opts.name,
        frame=opts.frame,
        storage=opts.storage,
        seed=opts.seed,
    )
    if stored is not None:
        rep["rotation_columns"] = {"kind": stored[0], "columns": list(stored[1])}
    return rep


def _infer_landmarks(table: DataTable, opts: InferOptions) -> dict:
    """The landmark ranking: a 68-point template fitted to each face, the systems ranked by the residual."""
    frame_df, data = table.frame, table.path
    P = numeric(frame_df, _landmark_columns(table.landmarks3d), data).reshape(-1, 68, 3)
    fit = fit_template(to_canonical_points(P, opts.landmark_frame))
    ids = frame_df["file"].astype(str).tolist() if "file" in frame_df.columns else None
    rep = inf.infer_landmarks(
        table.pyr,
        fit["R"],
        roles=table.roles,
        source=str(data),
        row_ids=ids,
        fit_rmse=fit["rmse_rel"],
        fit_rmse_limit=POOR_FIT_RMSE,
        seed=opts.seed,
        name=opts.name,
    )
    rep["template"] = {
        "source": "hpe_cli/data/reference_3d_68_points_trans.npy (DirectMHP mean iBUG-68), "
        "frame x right, y down, z into the head",
        "landmark_frame": opts.landmark_frame,
        "median_fit_rmse_template_units": float(np.nanmedian(fit["rmse_rel"])),
    }
    return rep
