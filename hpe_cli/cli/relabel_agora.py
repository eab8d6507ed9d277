"""``hpe relabel-agora``: head-pose labels from AGORA ground-truth dataframes."""

from __future__ import annotations

import click

from .options import (
    deprecated_spellings,
    echo_summary,
    format_from_suffix,
    format_option,
    image_size_option,
    label_frame_option,
    label_system_option,
    max_rmse_option,
    non_negative_or_inf,
    output_option,
    overwrite_option,
    preset_option,
    progress,
    rejects_options,
    threads_option,
    verbosity_options,
)


@deprecated_spellings("image-size")
@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("dataframes", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@output_option(help="Output: a .parquet/.csv table, or with --format coco a .json, with --format whenet a .txt.")
@label_system_option("DirectMHP's/WHENet's")
@format_option
@image_size_option(
    default="3840x2160",
    show_default=True,
    help="Size of the images the labels are for. AGORA renders 3840x2160 and ships 1280x720 copies; "
    "camK (and so the boxes and 2-D points) is rescaled from the size the dataframe was built for "
    "(read from camK's principal point, which AGORA puts at the image centre).",
)
@preset_option("directmhp")
@max_rmse_option("m", 2, "DirectMHP used no threshold: inf")
@click.option(
    "--max-occlusion",
    type=float,
    default=90.0,
    show_default=True,
    callback=non_negative_or_inf,
    metavar="PCT",
    help="Label only people with occlusion < PCT percent (DirectMHP: 90).",
)
@click.option(
    "--legacy-whenet",
    is_flag=True,
    help="Label with DirectMHP's chain, which is WHENet's (compound, Z-Y-X decomposition, "
    "select_euler, negation), and drop what it drops; adds legacy_pitch/yaw/roll columns.",
)
@label_frame_option
@click.option(
    "--trust-pickle",
    is_flag=True,
    help="Load any pickle, even one that asks for more than a pandas DataFrame needs. A pickle can run "
    "code: only for files you trust.",
)
@rejects_options
@overwrite_option
@threads_option
@verbosity_options
def relabel_agora(
    dataframes,
    output,
    system,
    fmt,
    image_size,
    preset,
    max_rmse,
    max_occlusion,
    legacy_whenet,
    label_frame,
    trust_pickle,
    rejects,
    strict,
    overwrite,
    threads,
    verbose,
    quiet,
):
    """Relabel AGORA: one head-pose label per person, from SMPL-X face joints.

    DATAFRAMES are AGORA ground-truth dataframes (*_withjv.pkl, pandas
    pickles, or the same converted to Parquet; recognised by content).
    Pickles are loaded by a restricted unpickler that builds only the
    pandas/numpy objects a dataframe is made of; one that asks for more is
    refused with the command that converts it to Parquet (or use
    --trust-pickle for files you trust). Each needs the columns imgPath, isValid,
    occlusion, and either DirectMHP's cam_j3d, camR, camT, camK or AGORA's
    gt_joints_3d (then the joints are read in the camera frame and the
    intrinsics are rebuilt by AGORA's rule: 36 x 20.25 mm sensor, focal length
    by scene); a missing column is an error naming the file and the column.

    For each person with occlusion < --max-occlusion and isValid, WHENet's
    58-point reference head is fitted to the 13 face joints DirectMHP pairs
    with it (SMPL-X joints 76-126 are the iBUG points 17-67); fits with RMSE
    above --max-rmse are rejected. The label is the corrected
    A = E @ camR @ R_head (E = diag(1, -1, -1)), the 300W-LP matrix of the
    head as the camera sees it, written in --system; the box is DirectMHP's
    helmet; the 51 face joints are projected to 2-D.

    The table has source, row, person, image (imgPath), bbox_x/y/w/h (pixels),
    the columns of `hpe convert` (pitch, yaw, roll, pitch_2.., r00..r22,
    gimbal_lock, roundtrip_err), fit_rmse (m), n_pairs, scale (m per
    reference-head unit), occlusion, image_width, image_height and
    lm0_x..lm50_y. --format coco writes DirectMHP's COCO JSON (euler_angles
    [pitch, yaw, roll], face2d_pts, bbox [x, y, w, h]); --format whenet
    writes WHENet's annotation.txt lines (image,yaw,pitch,roll). Both store
    whenet-system angles. Every person not labelled (occluded, invalid, too
    few points, bad fit, behind camera, outside image, box rejected, dropped
    by the legacy rule) is listed by --rejects with its reason and counted in
    the summary.

    Every field is checked at the door. A field of the wrong type or shape
    (cam_j3d or occlusion given as text, isValid 'no', imgPath missing) is an
    error naming the file, row, person and field. A person whose values are
    invalid (camR not a rotation, camK without positive focal lengths or
    principal point, occlusion outside 0-100, absurd joints, an image path
    with '..') is a 'bad input' reject with --rejects, and an error without
    it. The same dataframe given twice, or two with the same file name (the
    source column would repeat), is refused.

    \b
    Examples:
      hpe relabel-agora validation_*_withjv.pkl -o agora_val.parquet
      hpe relabel-agora train_0_withjv.pkl -o train.json --format coco --image-size 1280x720
      hpe relabel-agora val_0_withjv.pkl -o annotation.txt --legacy-whenet --max-rmse inf
      hpe relabel-agora val_0_withjv.pkl -o labels.csv --system 6drepnet --rejects rejects.csv
      hpe relabel-agora val_0_withjv.pkl -o crops.parquet --frame crop
    """
    from ..pipelines.relabel import FormatSystemError, RelabelAgoraOptions, run_relabel_agora

    try:
        opts = RelabelAgoraOptions(
            system=system,
            fmt=fmt or format_from_suffix(output),
            image_size=image_size,
            preset=preset,
            max_rmse=max_rmse,
            max_occlusion=max_occlusion,
            legacy=legacy_whenet,
            frame=label_frame,
            trust_pickle=trust_pickle,
            rejects=rejects,
            strict=strict,
            overwrite=overwrite,
            threads=threads,
        )
    except FormatSystemError as exc:
        raise click.UsageError(str(exc)) from None
    bar = lambda total: progress(total=total, desc="relabel-agora", quiet=quiet, unit="files")  # noqa: E731
    stats = run_relabel_agora(dataframes, output, opts, progress=bar)
    echo_summary(stats.summary(opts.config(), output, rejects, verbose), quiet)
