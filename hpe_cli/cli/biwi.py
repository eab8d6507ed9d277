"""``hpe biwi``: BIWI Kinect Head Pose labels as shipped -> a label table."""

from __future__ import annotations

import click

from .choices import RegistryChoice
from .options import (
    SYSTEM,
    echo_summary,
    output_option,
    overwrite_option,
    rejects_options,
    threads_option,
    verbosity_options,
)


def _fractions(ctx, param, value):
    if value is None:
        return None
    try:
        fr = tuple(float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected fractions such as 0.7,0.3, got {value!r}") from None
    if len(fr) < 2 or any(f < 0 for f in fr) or abs(sum(fr) - 1) > 1e-9:
        raise click.BadParameter(f"expected two or three fractions >= 0 summing to 1, got {value!r}")
    return fr


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@output_option()
@click.option(
    "--camera",
    type=click.Choice(["depth", "rgb"]),
    default="depth",
    show_default=True,
    help="Labels in the depth camera (as annotated) or the RGB camera (applies each sequence's rgb.cal).",
)
@click.option(
    "--calibration",
    type=click.Path(exists=True, file_okay=False),
    help="Folder with NN/rgb.cal and NN/depth.cal (hpdb/); default: INPUT.",
)
@click.option(
    "--head-size",
    type=click.FloatRange(1, 1000),
    default=200.0,
    show_default=True,
    help="Diameter (mm) of the sphere around the head centre projected for the boxes.",
)
@click.option(
    "--system", "system", type=SYSTEM, default="biwi", show_default=True, help="Rotation system of the output labels."
)
@click.option(
    "--protocol",
    type=RegistryChoice("hpe_cli.datasets.biwi:PROTOCOLS"),
    default="all",
    show_default=True,
    help="Test subset: every frame, or Hopenet/6DRepNet's |300W-LP angles| <= 99.",
)
@click.option(
    "--split",
    callback=_fractions,
    metavar="F1,F2[,F3]",
    help="Deterministic split of the sequences (never one sequence in two splits), e.g. 0.7,0.3; "
    "adds a 'split' column.",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the sequence shuffle.")
@click.option(
    "--split-lists",
    type=click.Path(file_okay=False),
    help="Write <split>_sequences.txt (one sequence per line) into this folder.",
)
@rejects_options
@overwrite_option
@threads_option
@verbosity_options
def biwi(
    input,
    output,
    camera,
    calibration,
    head_size,
    system,
    protocol,
    split,
    seed,
    split_lists,
    rejects,
    strict,
    overwrite,
    threads,
    verbose,
    quiet,
):
    """Read BIWI Kinect Head Pose labels (hpdb/ pose.txt, db_annotations/ .bin or db_annotations.tgz).

    Writes one row per frame: the label in --system (matrix r00..r22 and
    angles), the head centre (mm) in the chosen camera, its projection
    center_u, center_v and a square head box bbox_x, bbox_y, bbox_w, bbox_h
    (the image of a --head-size sphere around the head centre).

    Files are checked at the door: a pose must be a rotation with the head
    centre in front of the camera (within 10 m), .bin angles within a Z-Y-X
    split's range, rgb.cal/depth.cal a real camera (positive focal lengths,
    principal point inside the image, distortion a real lens has, R a
    rotation). Two files or archive members that are the same sequence and
    frame, a member stored twice, and members named with '..' or an absolute
    path are refused, naming them. A frame whose pose file is unreadable or
    invalid goes to --rejects (file, sequence, frame, reason); without
    --rejects, or with --strict, it is an error and nothing is written.

    \b
    Examples:
      hpe biwi hpdb/ -o biwi.parquet
      hpe biwi hpdb/ -o biwi_rgb.parquet --camera rgb --system 300w_lp
      hpe biwi db_annotations.tgz -o biwi.parquet --camera rgb --calibration hpdb/
      hpe biwi hpdb/ -o biwi.parquet --split 0.7,0.3 --seed 0 --split-lists splits/
      hpe biwi db_annotations/ -o biwi.parquet --rejects biwi_rejects.csv
    """
    from ..pipelines.biwi import BiwiOptions, run_biwi, summary_lines

    opts = BiwiOptions(
        camera=camera,
        calibration=calibration,
        head_size=head_size,
        system=system,
        protocol=protocol,
        split=split,
        seed=seed,
        split_lists=split_lists,
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        threads=threads,
    )
    echo_summary(summary_lines(run_biwi(input, output, opts), output, opts), quiet)
