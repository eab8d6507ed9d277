"""``hpe infer``'s job: load the user's code or read the data, run the search, report and write the answer.

The command line (:mod:`hpe_cli.cli.infer`) parses options and calls :func:`run_infer`
and :func:`finish`; the code search itself runs in a child process
(:mod:`hpe_cli.pipelines.infer_code`, which also loads the user's callable:
:func:`~hpe_cli.pipelines.infer_code.load_callable`).
"""

from __future__ import annotations

from ..errors import HpeError

ROLE_NAMES = ("pitch", "yaw", "roll")

#: stored rotation columns infer reads from a data table when it has no r00..r22 (see --rotations)
STORED_DEFAULTS = (("rotvec", ("rx", "ry", "rz")), ("quaternion-wxyz", ("qw", "qx", "qy", "qz")))


def matrix_columns(spec, columns) -> list | None:
    """The 9 matrix columns: ``spec`` (already 9 names) or ``r00..r22`` when the table has them, else None."""
    from ..io import MATRIX_COLS

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
    import numpy as np

    from ..rotation import storage as st

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


def code_file(spec: str):
    """The ``.py`` file of ``FILE.py:FUNC``, or None for ``module.path:FUNC``."""
    from pathlib import Path

    target = spec.rpartition(":")[0]
    if target and (target.endswith(".py") or Path(target).is_file()):
        return Path(target)
    return None


def read_data(path, units):
    from pathlib import Path

    from ..errors import HpeError

    p = Path(path)
    if p.is_dir() or p.suffix.lower() == ".mat":
        if units == "rad":
            raise HpeError(f"{path}: --radians does not apply to .mat files (Pose_Para is read in degrees)")
        from ..datasets.mat import read_mat_dir

        return read_mat_dir(p, landmarks=True), "deg"
    from ..io import read_table

    return read_table(p), units or "deg"


#: table kinds whose values are typed (no unparseable row to set aside) or one-record files
_NOT_TEXT = (".parquet", ".pq", ".arrow", ".feather", ".mat")


def read_text_table_with_rejects(path):
    """A text table with the rows the reader cannot parse set aside: ``(frame, file line of each row, [Reject])``
    (``--rejects``: such a row is a reject, as in every command, not the end of the run)."""
    import pyarrow as pa

    from ..io import open_table
    from ..io.readers import LINE_COL

    src = open_table(path, with_lines=True)
    batches, read_rejects = [], []
    for b, rr in src.batches_with_rejects():
        batches.append(b)
        read_rejects += rr
    frame = pa.Table.from_batches(batches, schema=src.schema).to_pandas()
    lines = frame.pop(LINE_COL).to_numpy()
    return frame, lines, read_rejects


def _set_aside_unusable(
    frame_df, pyr, data, mcols, stored, landmarks3d, rejects_path, strict, overwrite, lines=None, read_rejects=()
):
    """Rows whose angles or rotation values are missing or not finite cannot take part in the search: they go to
    ``--rejects`` with their reason (named ``FILE: line N`` / ``row N`` / the ``.mat`` file), and without a
    rejects file (or with ``--strict``) they are an error, as in every command that reads rows."""
    import numpy as np

    from ..io import Rejects
    from ..io.table_source import row_name

    if stored is not None:
        cols = list(stored[1])
    elif mcols is not None:
        cols = list(mcols)
    else:
        cols = [f"{landmarks3d}{i}_{a}" for i in range(68) for a in "xyz"]
    cols = [c for c in cols if c in frame_df.columns]
    values = numeric(frame_df, cols, data) if cols else np.zeros((len(frame_df), 0))
    bad_angles = ~np.isfinite(pyr).all(axis=1)
    bad_values = ~np.isfinite(values).all(axis=1)
    bad = bad_angles | bad_values
    if not bad.any() and not read_rejects:
        return frame_df, pyr
    from pathlib import Path

    p = Path(str(data))
    idx = np.flatnonzero(bad)
    if "file" in frame_df.columns and (p.is_dir() or p.suffix.lower() == ".mat"):
        rows = frame_df["file"].astype(str).to_numpy()[idx]  # one-record files name themselves
    else:
        text = p.suffix.lower() not in (".parquet", ".pq", ".arrow", ".feather")
        rows = idx + (2 if text else 1)  # text: file line (header = line 1); tables: 1-based row
        if lines is not None:  # rows were set aside while reading: each keeps its own file line
            rows = np.asarray(lines)[idx]
    reasons = np.where(
        bad_angles[idx],
        "angle not finite (missing, NaN or infinite)",
        "rotation value not finite (missing, NaN or infinite)",
    ).astype(object)
    rej = Rejects(rejects_path, overwrite, strict=strict, source=str(data))
    if read_rejects:
        read_lines = np.array([r.line for r in read_rejects], dtype=np.int64)
        rej.add(
            {"input": np.full(len(read_lines), str(data), dtype=object), "row": read_lines},
            [r.reason for r in read_rejects],
            where=row_name(str(data), int(read_lines[0])),
        )
    if len(idx):
        rej.add(
            {"input": np.full(len(idx), str(data), dtype=object), "row": rows},
            reasons,
            where=row_name(str(data), rows[0]),
        )
    rej.finish()
    keep = ~bad
    return frame_df[keep].reset_index(drop=True), pyr[keep]


def numeric(frame, cols, path):
    import numpy as np

    from ..errors import HpeError

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


def _small(x, spec: str = ".2g") -> str:
    """``x`` to 2 digits, or ``< 1e-12`` at rounding level (its digits differ between CPUs; as
    :func:`hpe_cli.cli.options.fmt_small`)."""
    return "< 1e-12" if 0 <= float(x) < 1e-12 else format(float(x), spec)


def report_lines(rep: dict) -> list:
    """The human-readable summary of an infer report (:func:`hpe_cli.rotation.infer.report_json`), as lines."""
    lines = []
    echo = lines.append
    if rep["mode"] == "landmarks":
        m = rep["matched"]
        echo(
            f"best: {rep['best']} ({rep['fit']}; RMS residual {rep['rms_residual_deg']:.2f} deg, median "
            f"{rep['median_residual_deg']:.2f} deg over {rep['samples']} faces; next candidate "
            f"{rep['separation']:.1f}x worse)"
        )
        echo(f"  {m['formula']}")
        echo("  built-in readings of the labels (RMS / max residual, deg):")
        for h in rep["hypotheses"]:
            echo(f"    {h['rms_residual_deg']:7.2f} {h['max_residual_deg']:7.2f}  {', '.join(h['readings'])}")
        if rep.get("warning"):
            echo(f"  warning: {rep['warning']}")
        worst = sorted(rep["per_face"], key=lambda f: -f["residual_deg"])[:3]
        echo("  largest per-face residuals: " + ", ".join(f"{f['id']} {f['residual_deg']:.2f} deg" for f in worst))
        return lines
    if rep["fit"] == "exact":
        m = rep["matched"]
        echo(
            f"best: {rep['best']} (exact; max Frobenius error {_small(rep['max_error'])} over {rep['samples']} samples)"
        )
        echo(f"  {m['formula']}")
        echo(f"  {m['turns']}")
        if m["transpose_of"]:
            echo(f"  (the transpose of the matrix of {', '.join(m['transpose_of'])})")
        if rep.get("also_matches"):
            echo(
                f"  also reproduced by built-in: {', '.join(rep['also_matches']['names'])} "
                "(same matrix from the same angles)"
            )
        if rep.get("selection"):
            echo(f"  solution kept by the decoder: {rep['selection']['rule']}")
        if rep.get("near_lock"):
            echo(
                f"  {rep['near_lock']['count']} samples near gimbal lock handled differently "
                f"(max error {_small(rep['near_lock']['max_error'])})"
            )
        if rep.get("ambiguous"):
            echo(f"  warning: {rep['ambiguous']}")
    else:
        m = rep["best_partial"]
        names = f" ({', '.join(m['builtins'])})" if m["builtins"] else ""
        echo(
            f"no exact fit. best partial fit: {m['formula']}{names}: {m['explained']} of {rep['samples']} "
            f"samples explained, median error {_small(m['median_error'], '.3g')}"
        )
        if "breaks" in m:
            echo(f"  {m['breaks']['summary']}")
    for e in rep.get("runners_up", [])[:3]:
        echo(f"  runner-up: {e['formula']}  max error {_small(e['max_error'], '.3g')}")
    return lines


def infer_data(
    data, frame_df, pyr, roles, units, mcols, landmarks3d, landmark_frame, tol, seed, name, frame, storage, stored=None
) -> dict:
    """The table search (matrix or stored rotation columns) or the landmark ranking (3-D landmark columns)."""
    import numpy as np

    from ..rotation import infer as inf

    if landmarks3d is None:
        if stored is not None:
            R = stored_to_matrices(stored[0], numeric(frame_df, stored[1], data))
        else:
            R = numeric(frame_df, mcols, data).reshape(-1, 3, 3)
        rep = inf.infer_table(
            pyr,
            R,
            roles=roles,
            units="degrees" if units == "deg" else "radians",
            tol=tol or inf.DATA_TOL,
            source=str(data),
            name=name,
            frame=frame,
            storage=storage,
            seed=seed,
        )
        if stored is not None:
            rep["rotation_columns"] = {"kind": stored[0], "columns": list(stored[1])}
        return rep
    from ..geometry.template import POOR_FIT_RMSE, fit_template, to_canonical_points

    lcols = [f"{landmarks3d}{i}_{a}" for i in range(68) for a in "xyz"]
    P = numeric(frame_df, lcols, data).reshape(-1, 68, 3)
    fit = fit_template(to_canonical_points(P, landmark_frame))
    ids = frame_df["file"].astype(str).tolist() if "file" in frame_df.columns else None
    rep = inf.infer_landmarks(
        pyr,
        fit["R"],
        roles=roles,
        source=str(data),
        row_ids=ids,
        fit_rmse=fit["rmse_rel"],
        fit_rmse_limit=POOR_FIT_RMSE,
        seed=seed,
        name=name,
    )
    rep["template"] = {
        "source": "hpe_cli/data/reference_3d_68_points_trans.npy (DirectMHP mean iBUG-68), "
        "frame x right, y down, z into the head",
        "landmark_frame": landmark_frame,
        "median_fit_rmse_template_units": float(np.nanmedian(fit["rmse_rel"])),
    }
    return rep


def run_infer(
    *,
    data=None,
    spec=None,
    builder=False,
    returns="angles",
    roles=ROLE_NAMES,
    packed=False,
    units=None,
    angle_columns=None,
    matrix=None,
    rotations=None,
    landmarks3d=None,
    landmark_frame="image",
    tol=None,
    samples=None,
    seed=0,
    name=None,
    frame=None,
    storage="active",
    timeout=None,
    import_path=(),
    rejects_path=None,
    strict=False,
    overwrite=False,
) -> dict:
    """The infer report of user code (``spec``: ``FILE.py:FUNC`` or ``module:FUNC``) or of a data table.

    Parameters mirror ``hpe infer``'s options; ``angle_columns`` is ``(roles, columns)`` of
    the table's angles, ``matrix`` 9 column names (None: ``r00..r22`` if present),
    ``rotations`` ``(kind, columns)`` (None: ``rx,ry,rz`` / ``qw,qx,qy,qz`` if present).

    Returns
    -------
    dict
        The report of :mod:`hpe_cli.rotation.infer`, with ``_system_toml`` and
        ``_system_name`` (None when nothing fits exactly).
    """
    import numpy as np

    from ..rotation import infer as inf

    if spec is not None:
        from ..io.transaction import note_input
        from .infer_code import DEFAULT_TIMEOUT, run_code_inference

        path = code_file(spec)
        if path is not None:
            note_input(path)  # -o/--json may never be the user's own code
        u = "degrees" if units == "deg" else "radians"
        rep, toml, system_name = run_code_inference(
            spec,
            builder=builder,
            roles=list(roles),
            units=u,
            packed=packed,
            samples=samples,
            timeout=DEFAULT_TIMEOUT if timeout is None else timeout,
            tol=tol or inf.CODE_TOL,
            seed=seed,
            source=spec,
            name=name,
            frame=frame,
            storage=storage,
            import_path=list(import_path),
            returns=returns,
        )
        if rep["fit"] != "exact" and units is None and returns == "angles":
            rep["hint"] = "no fit with the default --radians; try --degrees"
        rep["_system_toml"], rep["_system_name"] = toml, system_name
        return rep
    from pathlib import Path

    lines, read_rejects = None, []
    dpath = Path(str(data))
    if rejects_path is not None and dpath.is_file() and dpath.suffix.lower() not in _NOT_TEXT:
        frame_df, lines, read_rejects = read_text_table_with_rejects(data)
        units = units or "deg"
    else:
        frame_df, units = read_data(data, units)
    roles, cols = angle_columns or (list(ROLE_NAMES), list(ROLE_NAMES))
    vals = numeric(frame_df, cols, data)
    if units == "rad":
        vals = np.rad2deg(vals)
    pyr = np.empty_like(vals)
    pyr[:, [ROLE_NAMES.index(r) for r in roles]] = vals
    mcols = matrix_columns(matrix, frame_df.columns) if landmarks3d is None else None
    stored = None
    if landmarks3d is None and (rotations is not None or mcols is None):
        stored = stored_rotations(rotations, frame_df.columns)
    if landmarks3d is None and mcols is None and stored is None:
        if "lm3d0_x" not in frame_df.columns:
            raise HpeError(
                f"{data}: found neither matrix columns r00..r22, stored rotations (rx,ry,rz or "
                "qw,qx,qy,qz) nor 3-D landmarks lm3d0_x..; use --matrix, --rotations or --landmarks3d"
            )
        landmarks3d = "lm3d"
    frame_df, pyr = _set_aside_unusable(
        frame_df, pyr, data, mcols, stored, landmarks3d, rejects_path, strict, overwrite, lines, read_rejects
    )
    try:
        rep = infer_data(
            data,
            frame_df,
            pyr,
            roles,
            units,
            mcols,
            landmarks3d,
            landmark_frame,
            tol,
            seed,
            name,
            frame,
            storage,
            stored,
        )
    except ValueError as exc:
        raise HpeError(f"{data}: {exc}") from None
    system = rep.get("_system")
    rep["_system_toml"] = system.to_toml() if system is not None else None
    rep["_system_name"] = system.name if system is not None else None
    return rep


def finish(rep: dict, what: str, *, json_path=None, output=None, overwrite=False, echo=None) -> tuple:
    """Write the JSON report, show its summary (``echo`` per line) and, for a fit, write the system TOML.

    Returns ``(report, written)``: the JSON report and the ``wrote ...`` line (None without ``output``).

    Raises
    ------
    HpeError
        Nothing fits (the JSON report is still kept: it explains why; nothing is
        written to ``output``).
    """
    from ..io import AtomicFile, write_json
    from ..rotation import infer as inf

    report = inf.report_json(rep)
    if json_path is not None:
        write_json(report, json_path, overwrite)
    if echo is not None:
        for line in report_lines(report):
            echo(line)
    if rep["fit"] not in ("exact", "clear"):
        from ..io.transaction import current

        txn = current()
        if txn is not None:  # the report explains the failure: keep it (nothing is written with -o)
            txn.commit()
        tail = "; nothing written to " + output if output else ""
        if rep["mode"] == "landmarks":
            raise HpeError(
                f"{what}: no system explains the landmarks clearly ({rep['fit']}: best {rep['best']}, "
                f"RMS residual {rep['rms_residual_deg']:.2f} deg){tail}"
            )
        raise HpeError(
            f"{what}: no rotation system reproduces it exactly (best partial fit "
            f"{rep['best_partial']['formula']}, max error {_small(rep['max_error'], '.3g')}){tail}"
        )
    written = None
    if output is not None:
        with AtomicFile(output, overwrite) as tmp:
            tmp.write_text(rep["_system_toml"], encoding="utf-8")
        written = f"wrote {output} (system {rep['_system_name']})"
    return report, written
