"""``hpe infer``: find the rotation system a piece of code or a dataset uses."""
from __future__ import annotations

import click

from .table_options import column_options

from .options import SYSTEM, deprecated_spellings, overwrite_option, verbosity_options

ROLE_NAMES = ("pitch", "yaw", "roll")


def _roles(value: str, opt: str) -> list:
    roles = [v.strip().lower() for v in value.split(",")]
    if sorted(roles) != sorted(ROLE_NAMES):
        raise click.BadParameter(f"expected the three roles pitch, yaw, roll in some order, got {value!r}",
                                 param_hint=opt)
    return roles


def _angle_columns(value: str):
    """``pitch,yaw,roll`` or ``pitch=col_a,yaw=col_b,roll=col_c`` -> (roles, columns)."""
    roles, cols = [], []
    for item in value.split(","):
        role, _, col = item.partition("=")
        roles.append(role.strip().lower())
        cols.append(col.strip() or role.strip())
    if sorted(roles) != sorted(ROLE_NAMES):
        raise click.BadParameter(f"expected pitch, yaw, roll (optionally ROLE=COLUMN), got {value!r}",
                                 param_hint="--angles")
    return roles, cols


def _matrix_columns(value: str | None, columns) -> list | None:
    from ..io import MATRIX_COLS

    ij = [f"{i}{j}" for i in range(3) for j in range(3)]
    if value is None:
        return MATRIX_COLS if set(MATRIX_COLS) <= set(columns) else None
    if "," in value:
        cols = [c.strip() for c in value.split(",")]
        if len(cols) != 9:
            raise click.BadParameter(f"expected 9 comma-separated columns, got {len(cols)}", param_hint="--matrix")
        return cols
    prefix = value.split("..")[0]
    prefix = prefix[:-2] if prefix.endswith("00") else prefix
    return [prefix + s for s in ij]


#: stored rotation columns infer reads from a data table when it has no r00..r22 (see --rotations)
STORED_DEFAULTS = (("rotvec", ("rx", "ry", "rz")), ("quaternion-wxyz", ("qw", "qx", "qy", "qz")))


def _stored_rotations(value: str | None, columns):
    """``(kind, columns)`` of stored rotation values in a data table, or None.

    ``value`` is ``KIND:COL,COL,...`` with KIND one of rotvec (radians),
    quaternion-wxyz, quaternion-xyzw or 6d (matrix columns 0 and 1); without
    it, ``rx,ry,rz`` or ``qw,qx,qy,qz`` are used when present.
    """
    kinds = {"rotvec": 3, "quaternion-wxyz": 4, "quaternion-xyzw": 4, "6d": 6}
    if value is None:
        for kind, cols in STORED_DEFAULTS:
            if set(cols) <= set(columns):
                return kind, list(cols)
        return None
    kind, sep, cols = value.partition(":")
    if kind not in kinds or not sep:
        raise click.BadParameter(f"expected KIND:COLUMNS with KIND one of {', '.join(kinds)}, got {value!r}",
                                 param_hint="--rotations")
    names = [c.strip() for c in cols.split(",") if c.strip()]
    if len(names) != kinds[kind]:
        raise click.BadParameter(f"expected {kinds[kind]} columns for {kind}, got {len(names)}",
                                 param_hint="--rotations")
    return kind, names


def _stored_to_matrices(kind, values):
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


def _module_name_of(path):
    """``(root, "pkg.sub.mod")`` for a file inside a package, else None.

    Walks up the folders that hold an ``__init__.py``; a folder without one is
    still taken as a (namespace) package when the file uses relative imports
    (3DDFA_V2's ``utils/pose.py`` does ``from .functions import ...`` and
    ``utils/`` has no ``__init__.py``).
    """
    import re

    path = path.resolve()
    parts, folder = [], path.parent
    while (folder / "__init__.py").is_file() and folder.parent != folder:
        parts.insert(0, folder.name)
        folder = folder.parent
    if not parts:
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return None
        if not re.search(r"^\s*from\s+\.", text, re.M):
            return None
        parts, folder = [path.parent.name], path.parent.parent
    if not all(p.isidentifier() for p in parts) or not path.stem.isidentifier():
        return None
    return folder, ".".join(parts + [path.stem])


def _load_callable(spec: str, path=None):
    """``path/to/file.py:func`` or ``package.module:func`` (``func`` may be ``Class.method``).

    A file inside a package is imported as that package's module (so its
    relative imports work); ``path`` (folders) is put on ``sys.path`` first,
    for ``package.module:func`` specs that live outside the installed packages.
    """
    import importlib
    import importlib.util
    import sys
    from pathlib import Path

    from ..errors import HpeError

    target, sep, attr = spec.rpartition(":")
    if not sep or not target or not attr:
        raise HpeError(f"{spec}: expected FILE.py:FUNC or module.path:FUNC")
    for root in reversed([str(Path(p).resolve()) for p in (path or ())]):
        if root not in sys.path:
            sys.path.insert(0, root)
    file = Path(target)
    try:
        if target.endswith(".py") or file.exists():
            if not file.is_file():
                raise HpeError(f"{target}: no such file")
            found = _module_name_of(file)
            top = found[1].split(".")[0] if found else None
            if found is not None and (top not in sys.modules or
                                      str(found[0]) in str(getattr(sys.modules[top], "__path__", ""))):
                root, dotted = found
                for folder in (str(root), str(file.resolve().parent)):
                    if folder not in sys.path:
                        sys.path.insert(0, folder)  # the package root, and the file's siblings
                module = importlib.import_module(dotted)
            else:
                name = f"_hpe_infer_{abs(hash(str(file.resolve())))}"
                mod_spec = importlib.util.spec_from_file_location(name, file)
                module = importlib.util.module_from_spec(mod_spec)
                sys.modules[name] = module  # dataclasses and pickling look their module up here
                folder = str(file.resolve().parent)
                sys.path.insert(0, folder)  # let the file import its siblings
                try:
                    mod_spec.loader.exec_module(module)
                finally:
                    if folder in sys.path:
                        sys.path.remove(folder)
        else:
            module = importlib.import_module(target)
    except HpeError:
        raise
    except Exception as exc:
        hint = ""
        if "relative import" in str(exc):
            hint = " (the file is not inside a package: give module:FUNC with --path ROOT)"
        raise HpeError(f"{target}: import failed: {type(exc).__name__}: "
                       f"{' '.join(str(exc).split())[:200]}{hint}") from None
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise HpeError(f"{target}: has no attribute {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise HpeError(f"{spec}: expected a callable, got {type(obj).__name__}")
    return obj


def _code_file(spec: str):
    """The ``.py`` file of ``FILE.py:FUNC``, or None for ``module.path:FUNC``."""
    from pathlib import Path

    target = spec.rpartition(":")[0]
    if target and (target.endswith(".py") or Path(target).is_file()):
        return Path(target)
    return None


def _read_data(path, units):
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


def _numeric(frame, cols, path):
    import numpy as np

    from ..errors import HpeError

    missing = [c for c in cols if c not in frame.columns]
    if missing:
        raise HpeError(f"{path}: missing column(s) {', '.join(missing[:6])}{' ...' if len(missing) > 6 else ''}; "
                       f"expected {', '.join(cols[:3])}{' ...' if len(cols) > 3 else ''}")
    try:
        return frame[cols].to_numpy(dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise HpeError(f"{path}: columns {', '.join(cols[:3])}...: expected numbers ({exc})") from None


def _print_report(rep: dict, quiet: bool) -> None:
    if quiet:
        return
    echo = click.echo
    if rep["mode"] == "landmarks":
        m = rep["matched"]
        echo(f"best: {rep['best']} ({rep['fit']}; RMS residual {rep['rms_residual_deg']:.2f} deg, median "
             f"{rep['median_residual_deg']:.2f} deg over {rep['samples']} faces; next candidate "
             f"{rep['separation']:.1f}x worse)")
        echo(f"  {m['formula']}")
        echo("  built-in readings of the labels (RMS / max residual, deg):")
        for h in rep["hypotheses"]:
            echo(f"    {h['rms_residual_deg']:7.2f} {h['max_residual_deg']:7.2f}  {', '.join(h['readings'])}")
        if rep.get("warning"):
            echo(f"  warning: {rep['warning']}")
        worst = sorted(rep["per_face"], key=lambda f: -f["residual_deg"])[:3]
        echo("  largest per-face residuals: " + ", ".join(f"{f['id']} {f['residual_deg']:.2f} deg" for f in worst))
        return
    if rep["fit"] == "exact":
        m = rep["matched"]
        echo(f"best: {rep['best']} (exact; max Frobenius error {rep['max_error']:.2g} over {rep['samples']} samples)")
        echo(f"  {m['formula']}")
        echo(f"  {m['turns']}")
        if m["transpose_of"]:
            echo(f"  (the transpose of the matrix of {', '.join(m['transpose_of'])})")
        if rep.get("also_matches"):
            echo(f"  also reproduced by built-in: {', '.join(rep['also_matches']['names'])} "
                 "(same matrix from the same angles)")
        if rep.get("selection"):
            echo(f"  solution kept by the decoder: {rep['selection']['rule']}")
        if rep.get("near_lock"):
            echo(f"  {rep['near_lock']['count']} samples near gimbal lock handled differently "
                 f"(max error {rep['near_lock']['max_error']:.2g})")
        if rep.get("ambiguous"):
            echo(f"  warning: {rep['ambiguous']}")
    else:
        m = rep["best_partial"]
        names = f" ({', '.join(m['builtins'])})" if m["builtins"] else ""
        echo(f"no exact fit. best partial fit: {m['formula']}{names}: {m['explained']} of {rep['samples']} "
             f"samples explained, median error {m['median_error']:.3g}")
        if "breaks" in m:
            echo(f"  {m['breaks']['summary']}")
    for e in rep.get("runners_up", [])[:3]:
        echo(f"  runner-up: {e['formula']}  max error {e['max_error']:.3g}")


def _infer_data(data, frame_df, pyr, roles, units, mcols, landmarks3d, landmark_frame, tol, seed, name, frame,
                storage, stored=None) -> dict:
    """The table search (matrix or stored rotation columns) or the landmark ranking (3-D landmark columns)."""
    import numpy as np

    from ..rotation import infer as inf

    if landmarks3d is None:
        if stored is not None:
            R = _stored_to_matrices(stored[0], _numeric(frame_df, stored[1], data))
        else:
            R = _numeric(frame_df, mcols, data).reshape(-1, 3, 3)
        rep = inf.infer_table(pyr, R, roles=roles, units="degrees" if units == "deg" else "radians",
                               tol=tol or inf.DATA_TOL, source=str(data), name=name, frame=frame, storage=storage,
                               seed=seed)
        if stored is not None:
            rep["rotation_columns"] = {"kind": stored[0], "columns": list(stored[1])}
        return rep
    from ..geometry.template import POOR_FIT_RMSE, fit_template, to_canonical_points

    lcols = [f"{landmarks3d}{i}_{a}" for i in range(68) for a in "xyz"]
    P = _numeric(frame_df, lcols, data).reshape(-1, 68, 3)
    fit = fit_template(to_canonical_points(P, landmark_frame))
    ids = frame_df["file"].astype(str).tolist() if "file" in frame_df.columns else None
    rep = inf.infer_landmarks(pyr, fit["R"], roles=roles, source=str(data), row_ids=ids, fit_rmse=fit["rmse_rel"],
                              fit_rmse_limit=POOR_FIT_RMSE, seed=seed, name=name)
    rep["template"] = {"source": "hpe_cli/data/reference_3d_68_points_trans.npy (DirectMHP mean iBUG-68), "
                                 "frame x right, y down, z into the head", "landmark_frame": landmark_frame,
                       "median_fit_rmse_template_units": float(np.nanmedian(fit["rmse_rel"]))}
    return rep


@deprecated_spellings("units")
@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("data", required=False, type=click.Path(exists=True))
@click.option("--callable", "builder", metavar="FILE.py:FUNC",
              help="A function angles -> 3x3 matrix (a file path or a module path, then :FUNC).")
@click.option("--decoder", metavar="FILE.py:FUNC", help="A function 3x3 matrix -> three angles.")
@click.option("--returns", type=click.Choice(["angles", "stored"]), default="angles", show_default=True,
              help="--decoder returns three angles, or stored values (a rotation vector, quaternion, 6-D vector "
                   "or 9 matrix entries): then find which storage form and whether of the matrix or its transpose.")
@click.option("--args", "args_", default="pitch,yaw,roll", show_default=True,
              help="Role of each positional argument (--callable) or returned angle (--decoder).")
@click.option("--packed", is_flag=True, help="--callable takes one sequence of the three angles.")
@click.option("--radians/--degrees", "radians", default=None,
              help="Angle units of the code (default --radians) or of DATA's angle columns (default --degrees). "
                   "The old --units rad|deg still works, with a warning.")
@click.option("--angles", default="pitch,yaw,roll", show_default=True,
              help="DATA's angle columns, in storage order: ROLE or ROLE=COLUMN.")
@click.option("--matrix", "matrix_cols", default=None, metavar="COLS",
              help="DATA's matrix columns: r00..r22 (a prefix) or 9 comma-separated names.")
@click.option("--rotations", "rotation_cols", default=None, metavar="KIND:COLS",
              help="DATA's rotations as stored values instead of r00..r22: rotvec:rx,ry,rz (radians), "
                   "quaternion-wxyz:qw,qx,qy,qz, quaternion-xyzw:..., or 6d:six columns (matrix columns 0, 1). "
                   "Default: rx,ry,rz or qw,qx,qy,qz when present and r00..r22 are not.")
@click.option("--landmarks3d", default=None, metavar="PREFIX",
              help="DATA's 68 3-D landmark columns PREFIX{i}_x/_y/_z (AFLW2000 .mat: lm3d).")
@click.option("--landmark-frame", type=click.Choice(["image", "canonical", "opencv"]), default="image",
              show_default=True, help="Axes of the 3-D landmarks: image = x right, y down, z towards the camera; "
              "canonical = y up; opencv = y down, z away from the camera.")
@click.option("--tol", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Largest Frobenius error counted as equal (default 1e-6 for code, 1e-4 for tables).")
@click.option("--samples", type=click.IntRange(16, 100_000), default=None,
              help="Samples to call the code on (default 64 for --callable, 256 for --decoder).")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed of the samples.")
@click.option("--name", default=None, help="Name of a custom system written with -o.")
@click.option("--frame", "frame_of", type=SYSTEM, default=None,
              help="For a custom answer: take the frame from this system (code cannot reveal its frame).")
@click.option("--storage", type=click.Choice(["active", "transposed"]), default="active", show_default=True,
              help="For a custom answer: what the matrix means (code cannot reveal it).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None, help="Write the full report.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Write the matched system as a .toml file (for `hpe convert --from`).")
@click.option("--path", "import_path", multiple=True, type=click.Path(exists=True, file_okay=False),
              help="Folder to import module:FUNC from (a repository root); repeatable.")
@click.option("--timeout", type=click.FloatRange(min=0, min_open=True), default=60.0, show_default=True,
              help="Seconds the code of --callable/--decoder may run (it runs in a separate process).")
@overwrite_option
@verbosity_options
@column_options
def infer(data, builder, decoder, returns, args_, packed, radians, angles, matrix_cols, rotation_cols, landmarks3d,
          landmark_frame, tol,
          samples, seed, name, frame_of, storage, json_path, output, overwrite, verbose, quiet, timeout,
          import_path):
    """Find which rotation system a function or a dataset uses.

    With --callable, call the function on well-spread angles and find the
    system whose matrix equals it on every sample: any assignment of the
    angles to axes, any handedness, all 12 Tait-Bryan and proper Euler
    sequences, intrinsic or extrinsic, transposed or not. With --decoder
    (matrix -> angles), call it on random rotations and find the system that
    rebuilds them (samples near a gimbal lock may differ). With DATA (a
    .parquet/.csv table or a folder of .mat files), do the same on rows of
    angles and matrices (r00..r22 by default); or, with 3-D landmarks (used
    when there are no matrix columns, e.g. AFLW2000-3D pt3d_68), fit a
    68-point template to each face and rank the systems by the rotation
    residual (degrees).

    The answer is a built-in name when one matches (built-ins sharing one
    function are told apart by the decoder's solution rule, then --args order
    and units), else `custom`. A function cannot reveal its frame or whether
    its matrix is active: a custom answer uses --frame/--storage.
    If nothing fits (with landmarks: if no winner is clear), the best partial
    fit and where it breaks are reported and the exit status is 1 (nothing is
    written with -o).

    \b
    Examples:
      hpe infer --callable sixdrepnet.py:get_R --args pitch,yaw,roll
      hpe infer --decoder 3DDFA_V2/utils/pose.py:matrix2angle --args yaw,pitch,roll --json report.json
      hpe infer --decoder utils.pose:matrix2angle --path 3DDFA_V2 --args yaw,pitch,roll
      hpe infer --decoder mycode.py:to_rotvec --returns stored -o mine.toml
      hpe infer --callable mylib.pose:euler_to_matrix --args roll,pitch,yaw --degrees -o mine.toml
      hpe infer labels.parquet --angles pitch,yaw,roll --matrix r00..r22
      hpe infer preds.csv --angles pitch,yaw,roll --rotations rotvec:rx,ry,rz
      hpe infer AFLW2000/ --landmarks3d lm3d --json aflw_system.json
    """
    units = None if radians is None else ("rad" if radians else "deg")
    import numpy as np

    from ..errors import HpeError
    from ..io import AtomicFile, check_output, write_json
    from ..rotation import infer as inf

    modes = sum(x is not None for x in (data, builder, decoder))
    if modes != 1:
        raise click.UsageError("give exactly one of DATA, --callable FILE.py:FUNC or --decoder FILE.py:FUNC")
    if returns != "angles" and decoder is None:
        raise click.UsageError("--returns stored applies to --decoder only")
    if packed and builder is None:
        raise click.UsageError("--packed applies to --callable only")
    if output is not None:
        if not output.lower().endswith(".toml"):
            raise click.BadParameter(f"expected a .toml file, got {output!r}", param_hint="-o/--output")
        check_output(output, overwrite)
    if json_path is not None:
        check_output(json_path, overwrite)
    frame = frame_of.frame if frame_of is not None else None

    system_toml = system_name = None
    if builder or decoder:
        from ..io.transaction import note_input
        from ..pipelines.infer_code import run_code_inference

        spec = builder or decoder
        roles = _roles(args_, "--args")
        code_file = _code_file(spec)
        if code_file is not None:
            note_input(code_file)  # -o/--json may never be the user's own code
        u = "degrees" if units == "deg" else "radians"
        rep, system_toml, system_name = run_code_inference(
            spec, builder=bool(builder), roles=roles, units=u, packed=packed, samples=samples, timeout=timeout,
            tol=tol or inf.CODE_TOL, seed=seed, source=spec, name=name, frame=frame, storage=storage,
            import_path=list(import_path), returns=returns)
        if rep["fit"] != "exact" and units is None and returns == "angles":
            rep["hint"] = "no fit with the default --radians; try --degrees"
    else:
        frame_df, units = _read_data(data, units)
        roles, cols = _angle_columns(angles)
        vals = _numeric(frame_df, cols, data)
        if units == "rad":
            vals = np.rad2deg(vals)
        pyr = np.empty_like(vals)
        pyr[:, [ROLE_NAMES.index(r) for r in roles]] = vals
        mcols = _matrix_columns(matrix_cols, frame_df.columns) if landmarks3d is None else None
        stored = None
        if landmarks3d is None and (rotation_cols is not None or mcols is None):
            stored = _stored_rotations(rotation_cols, frame_df.columns)
        if landmarks3d is None and mcols is None and stored is None:
            if "lm3d0_x" in frame_df.columns:
                landmarks3d = "lm3d"
            else:
                raise HpeError(f"{data}: found neither matrix columns r00..r22, stored rotations (rx,ry,rz or "
                               "qw,qx,qy,qz) nor 3-D landmarks lm3d0_x..; use --matrix, --rotations or --landmarks3d")
        try:
            rep = _infer_data(data, frame_df, pyr, roles, units, mcols, landmarks3d, landmark_frame, tol, seed,
                              name, frame, storage, stored)
        except ValueError as exc:
            raise HpeError(f"{data}: {exc}") from None

    if "_system" in rep:
        system = rep["_system"]
        system_toml, system_name = system.to_toml(), system.name
    report = inf.report_json(rep)
    if json_path is not None:
        write_json(report, json_path, overwrite)
    _print_report(report, quiet)
    ok = rep["fit"] in ("exact", "clear")
    if not ok:
        from ..io.transaction import current

        txn = current()
        if txn is not None:  # the report explains the failure: keep it (nothing is written with -o)
            txn.commit()
        what = f"{spec}" if (builder or decoder) else str(data)
        if rep["mode"] == "landmarks":
            raise HpeError(f"{what}: no system explains the landmarks clearly ({rep['fit']}: best {rep['best']}, "
                           f"RMS residual {rep['rms_residual_deg']:.2f} deg)"
                           + ("; nothing written to " + output if output else ""))
        raise HpeError(f"{what}: no rotation system reproduces it exactly (best partial fit "
                       f"{rep['best_partial']['formula']}, max error {rep['max_error']:.3g})"
                       + ("; nothing written to " + output if output else ""))
    if output is not None:
        with AtomicFile(output, overwrite) as tmp:
            tmp.write_text(system_toml, encoding="utf-8")
        if not quiet:
            from .options import echo_summary

            echo_summary([f"wrote {output} (system {system_name})"])
