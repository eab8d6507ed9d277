"""``hpe infer``: find the rotation system a piece of code or a dataset uses."""

from __future__ import annotations

import click

from .options import SYSTEM, deprecated_spellings, overwrite_option, rejects_options, threads_option, verbosity_options
from .table_options import column_options


def _roles(value: str, opt: str) -> list:
    from ..pipelines.infer import ROLE_NAMES

    roles = [v.strip().lower() for v in value.split(",")]
    if sorted(roles) != sorted(ROLE_NAMES):
        raise click.BadParameter(
            f"expected the three roles pitch, yaw, roll in some order, got {value!r}", param_hint=opt
        )
    return roles


def _angle_columns(value: str):
    """``pitch,yaw,roll`` or ``pitch=col_a,yaw=col_b,roll=col_c`` -> (roles, columns)."""
    from ..pipelines.infer import ROLE_NAMES

    roles, cols = [], []
    for item in value.split(","):
        role, _, col = item.partition("=")
        roles.append(role.strip().lower())
        cols.append(col.strip() or role.strip())
    if sorted(roles) != sorted(ROLE_NAMES):
        raise click.BadParameter(
            f"expected pitch, yaw, roll (optionally ROLE=COLUMN), got {value!r}", param_hint="--angles"
        )
    return roles, cols


def _matrix_columns(value: str | None) -> list | None:
    """``--matrix``: 9 comma-separated names or a prefix (``r00..r22``); None: the table's ``r00..r22``."""
    if value is None:
        return None
    if "," in value:
        cols = [c.strip() for c in value.split(",")]
        if len(cols) != 9:
            raise click.BadParameter(f"expected 9 comma-separated columns, got {len(cols)}", param_hint="--matrix")
        return cols
    prefix = value.split("..")[0]
    prefix = prefix.removesuffix("00")
    return [prefix + f"{i}{j}" for i in range(3) for j in range(3)]


def _stored_rotations(value: str | None):
    """``--rotations KIND:COL,COL,...`` -> ``(kind, columns)``; None: the table's defaults (see the pipeline).

    KIND is one of rotvec (radians), quaternion-wxyz, quaternion-xyzw or 6d (matrix columns 0 and 1).
    """
    from ..pipelines.infer import ROTATION_KINDS as kinds

    if value is None:
        return None
    kind, sep, cols = value.partition(":")
    if kind not in kinds or not sep:
        raise click.BadParameter(
            f"expected KIND:COLUMNS with KIND one of {', '.join(kinds)}, got {value!r}", param_hint="--rotations"
        )
    names = [c.strip() for c in cols.split(",") if c.strip()]
    if len(names) != kinds[kind]:
        raise click.BadParameter(
            f"expected {kinds[kind]} columns for {kind}, got {len(names)}", param_hint="--rotations"
        )
    return kind, names


def _positive_seconds(ctx, param, value):
    """``--timeout``: a positive finite number of seconds (nan, inf, 0 and negatives are usage errors)."""
    import math

    if value is None:
        return value
    if not (math.isfinite(value) and value > 0):
        raise click.BadParameter(f"expected a positive finite number of seconds, got {value!r}")
    return value


@deprecated_spellings("units")
@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("data", required=False, type=click.Path(exists=True))
@click.option(
    "--callable",
    "builder",
    metavar="FILE.py:FUNC",
    help="A function angles -> 3x3 matrix (a file path or a module path, then :FUNC).",
)
@click.option("--decoder", metavar="FILE.py:FUNC", help="A function 3x3 matrix -> three angles.")
@click.option(
    "--returns",
    type=click.Choice(["angles", "stored"]),
    default="angles",
    show_default=True,
    help="--decoder returns three angles, or stored values (a rotation vector, quaternion, 6-D vector "
    "or 9 matrix entries): then find which storage form and whether of the matrix or its transpose.",
)
@click.option(
    "--args",
    "args_",
    default="pitch,yaw,roll",
    show_default=True,
    help="Role of each positional argument (--callable) or returned angle (--decoder).",
)
@click.option("--packed", is_flag=True, help="--callable takes one sequence of the three angles.")
@click.option(
    "--radians/--degrees",
    "radians",
    default=None,
    help="Angle units of the code (default --radians) or of DATA's angle columns (default --degrees). "
    "The old --units rad|deg still works, with a warning.",
)
@click.option(
    "--angles",
    default="pitch,yaw,roll",
    show_default=True,
    help="DATA's angle columns, in storage order: ROLE or ROLE=COLUMN.",
)
@click.option(
    "--matrix",
    "matrix_cols",
    default=None,
    metavar="COLS",
    help="DATA's matrix columns: r00..r22 (a prefix) or 9 comma-separated names.",
)
@click.option(
    "--rotations",
    "rotation_cols",
    default=None,
    metavar="KIND:COLS",
    help="DATA's rotations as stored values instead of r00..r22: rotvec:rx,ry,rz (radians), "
    "quaternion-wxyz:qw,qx,qy,qz, quaternion-xyzw:..., or 6d:six columns (matrix columns 0, 1). "
    "Default: rx,ry,rz or qw,qx,qy,qz when present and r00..r22 are not.",
)
@click.option(
    "--landmarks3d",
    default=None,
    metavar="PREFIX",
    help="DATA's 68 3-D landmark columns PREFIX{i}_x/_y/_z (AFLW2000 .mat: lm3d).",
)
@click.option(
    "--landmark-frame",
    type=click.Choice(["image", "canonical", "opencv"]),
    default="image",
    show_default=True,
    help="Axes of the 3-D landmarks: image = x right, y down, z towards the camera; "
    "canonical = y up; opencv = y down, z away from the camera.",
)
@click.option(
    "--tol",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Largest Frobenius error counted as equal (default 1e-6 for code, 1e-4 for tables).",
)
@click.option(
    "--samples",
    type=click.IntRange(16, 100_000),
    default=None,
    help="Samples to call the code on (default 64 for --callable, 256 for --decoder).",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed of the samples.")
@click.option("--name", default=None, help="Name of a custom system written with -o.")
@click.option(
    "--frame",
    "frame_of",
    type=SYSTEM,
    default=None,
    help="For a custom answer: take the frame from this system (code cannot reveal its frame).",
)
@click.option(
    "--storage",
    type=click.Choice(["active", "transposed"]),
    default="active",
    show_default=True,
    help="For a custom answer: what the matrix means (code cannot reveal it).",
)
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None, help="Write the full report.")
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    default=None,
    help="Write the matched system as a .toml file (for `hpe convert --from`).",
)
@click.option(
    "--path",
    "import_path",
    multiple=True,
    type=click.Path(exists=True, file_okay=False),
    help="Folder to import module:FUNC from (a repository root); repeatable.",
)
@click.option(
    "--timeout",
    type=float,
    callback=_positive_seconds,
    default=60.0,
    show_default=True,
    help="Seconds the code of --callable/--decoder may run (it runs in a separate process).",
)
@rejects_options
@overwrite_option
@threads_option
@verbosity_options
@column_options
def infer(
    data,
    builder,
    decoder,
    returns,
    args_,
    packed,
    radians,
    angles,
    matrix_cols,
    rotation_cols,
    landmarks3d,
    landmark_frame,
    tol,
    samples,
    seed,
    name,
    frame_of,
    storage,
    json_path,
    output,
    rejects,
    strict,
    overwrite,
    threads,
    verbose,
    quiet,
    timeout,
    import_path,
):
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
      hpe infer preds.csv --rejects unusable.csv    # rows with missing/NaN values set aside, not dropped silently
      hpe infer preds_rotvec.csv --angles pitch,yaw,roll --rotations rotvec:rx,ry,rz
      hpe infer AFLW2000/ --landmarks3d lm3d --json aflw_system.json
    """
    from ..io import check_output
    from ..pipelines.infer import ROLE_NAMES, InferOptions, finish, run_infer

    units = None if radians is None else ("rad" if radians else "deg")

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
    spec = builder or decoder
    opts = InferOptions(
        builder=bool(builder),
        returns=returns,
        roles=tuple(_roles(args_, "--args")) if spec else ROLE_NAMES,
        packed=packed,
        units=units,
        angle_columns=None if spec else _angle_columns(angles),
        matrix=_matrix_columns(matrix_cols),
        rotations=_stored_rotations(rotation_cols),
        landmarks3d=landmarks3d,
        landmark_frame=landmark_frame,
        tol=tol,
        samples=samples,
        seed=seed,
        name=name,
        frame=frame_of.frame if frame_of is not None else None,
        storage=storage,
        timeout=timeout,
        import_path=tuple(import_path),
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        threads=threads,
    )
    rep = run_infer(data, spec, opts)
    _, written = finish(
        rep,
        spec or str(data),
        json_path=json_path,
        output=output,
        overwrite=overwrite,
        echo=None if quiet else click.echo,
    )
    if written and not quiet:
        from .options import echo_summary

        echo_summary([written])
