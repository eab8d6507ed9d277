"""``hpe convert``: labels from one rotation system to another."""

from __future__ import annotations

import click

from .choices import RegistryChoice
from .options import (
    SYSTEM,
    batch_option,
    echo_summary,
    exclude_option,
    fmt_small,
    output_option,
    overwrite_option,
    progress,
    radians_option,  # the one spelling of input angle units
    rejects_options,
    threads_option,
    verbosity_options,
)
from .table_options import column_options


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@output_option()
@click.option(
    "--from",
    "source",
    type=SYSTEM,
    default=None,
    help="System of INPUT: built-in name or .toml file [default: the file's own (hpe:system metadata, "
    "dataset format); required for files that name none].",
)
@click.option("--to", "target", type=SYSTEM, required=True, help="System to write: built-in name or .toml file.")
@radians_option()
@click.option(
    "--decoder",
    type=RegistryChoice("hpe_cli.rotation.decoders:DECODERS"),
    default=None,
    help="Also write what this published decoder prints for each rotation (decoder_pitch, decoder_yaw, "
    "decoder_roll, decoder_ok), beside the exact angles. `hpe audit --decoder` measures the gap.",
)
@rejects_options
@exclude_option
@overwrite_option
@batch_option
@threads_option
@verbosity_options
@column_options
def convert(
    input,
    output,
    source,
    target,
    radians,
    decoder,
    rejects,
    strict,
    exclude,
    overwrite,
    batch_size,
    threads,
    verbose,
    quiet,
):
    """Convert head-pose labels between rotation systems.

    INPUT is a .parquet or .csv table with the source system's own value
    columns when it declares them (img2pose: rx,ry,rz radians; openface:
    pose_Rx..; mediapipe: m00..m22; trinet: left_x..front_z; quaternion
    systems: qw,qx,qy,qz; 6-D: sixd_0..sixd_5 -- see `hpe systems -v`), else
    angle columns pitch,yaw,roll (degrees), else matrix columns r00..r22
    (row-major, the source system's stored matrix); or a folder of
    300W-LP/AFLW2000 .mat files (read from Pose_Para, with a `file` column).

    OUTPUT (.parquet or .csv) keeps every other input column, then
    pitch,yaw,roll (primary solution; for systems that store no angles, the
    300W-LP angles), pitch_2,yaw_2,roll_2 (the other one), r00..r22 (target
    stored matrix), gimbal_lock and roundtrip_err (Frobenius distance between
    the input rotation and the one rebuilt from the output angles), then --
    in addition, never instead -- the target's own value columns when it
    declares them (rotation vector, quaternion with w >= 0, 6-D, 4x4 block,
    named angle columns in the system's units). Parquet metadata records the
    target system's definition.

    \b
    Examples:
      hpe convert labels.csv -o labels_6d.parquet --from 300w_lp --to 6drepnet
      hpe convert AFLW2000/ -o aflw_scipy.csv --from 300w_lp --to scipy_zyx
      hpe convert preds.parquet -o fixed.parquet --from my_system.toml --to 300w_lp --rejects bad.csv
      hpe convert rad.csv -o deg.csv --from 3ddfa_v2 --to 300w_lp --radians
      hpe convert img2pose_preds.csv -o preds_300wlp.csv --from img2pose --to 300w_lp
      hpe convert AFLW2000/ -o aflw_q.parquet --from 300w_lp --to my_quaternions.toml
      hpe convert AFLW2000/ -o synergy.csv --from 300w_lp --to 3ddfa_v2 --decoder synergynet
    """
    from ..pipelines.convert import ConvertOptions, run_convert

    options = ConvertOptions(
        radians=radians,
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        batch_size=batch_size,
        threads=threads,
        decoder=decoder,
        exclude=exclude,
    )
    bar = progress(desc="convert", quiet=quiet)
    try:
        s = run_convert(input, output, source, target, options, progress=bar)
    finally:
        bar.close()
    lines = [
        f"{s.written} of {s.rows} rows converted from {s.source} ({s.source_origin}) to {target.name} -> {output}",
        f"gimbal-locked rows: {s.gimbal_lock}; max round-trip error: {fmt_small(s.max_roundtrip_err)}",
    ]
    if s.excluded:
        lines.append(f"excluded: {s.excluded} rows listed in {exclude}" + (f" -> {rejects}" if rejects else ""))
    if s.rejects:
        lines.append(
            "rejected: "
            + "; ".join(f"{n} {r}" for r, n in sorted(s.rejects.items(), key=lambda x: -x[1]))
            + f" -> {rejects}"
        )
    echo_summary(lines, quiet)
