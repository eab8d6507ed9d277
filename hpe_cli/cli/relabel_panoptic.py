"""``hpe relabel-panoptic``: head-pose labels from CMU Panoptic 3-D face landmarks."""

from __future__ import annotations

import click

from .options import (
    echo_summary,
    format_from_suffix,
    format_option,
    label_frame_option,
    label_system_option,
    max_rmse_option,
    output_option,
    overwrite_option,
    preset_option,
    progress,
    rejects_options,
    resume_option,
    scheduler_option,
    verbosity_options,
)


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("seq_dirs", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False))
@output_option(help="Output: a .parquet/.csv table, or with --format coco a .json, with --format whenet a .txt.")
@click.option(
    "--calibration",
    type=click.Path(exists=True, dir_okay=False),
    help="Calibration JSON [default: SEQ_DIR/calibration_<seq>.json].",
)
@label_system_option("WHENet's")
@preset_option("whenet")
@format_option
@click.option(
    "--cameras",
    default="hd",
    show_default=True,
    help="hd (all 31 HD cameras), whenet-haggling (WHENet's 20-camera subset for the haggling "
    "sequences), or comma-separated camera names such as 00_00,00_08.",
)
@click.option(
    "--every",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="Frame step: keep frame numbers start, start+N, ... (looked up by number).",
)
@click.option(
    "--frames",
    "frame_range",
    default=None,
    metavar="A:B",
    help="Only frames A <= frame < B (either side may be empty).",
)
@click.option(
    "--min-change",
    type=click.FloatRange(0, 180, min_open=True),
    default=None,
    metavar="DEG",
    help="Keep a label only if it differs by at least DEG degrees (geodesic) from the last label "
    "kept for the same sequence, person and camera; the others go to the rejects.",
)
@click.option("--all-views", is_flag=True, help="Keep a face in a frame only if every selected camera labels it.")
@label_frame_option
@click.option("--no-landmarks", is_flag=True, help="Leave out the 140 projected landmark columns (faster).")
@click.option(
    "--workers",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="Worker processes; each computes units of 64 frames and writes its own parts.",
)
@scheduler_option
@resume_option(
    "calibration files are compared by their contents, face files and hdFace3d.tar by size, modification time and inode"
)
@max_rmse_option(
    "cm",
    2,
    "consistent faces of 160906_pizza1 fit to 0.6-1.3 cm, broken ones to 2.8-6.7 cm; WHENet used no threshold: inf",
)
@click.option(
    "--legacy-whenet",
    is_flag=True,
    help="Label with WHENet's own chain (compound, Z-Y-X decomposition, select_euler, negation) "
    "and drop what it drops; adds legacy_pitch/yaw/roll columns.",
)
@rejects_options
@overwrite_option
@verbosity_options
def relabel_panoptic(
    seq_dirs,
    output,
    calibration,
    system,
    preset,
    fmt,
    cameras,
    every,
    frame_range,
    min_change,
    all_views,
    label_frame,
    no_landmarks,
    workers,
    scheduler,
    resume,
    max_rmse,
    legacy_whenet,
    rejects,
    strict,
    overwrite,
    verbose,
    quiet,
):
    """Relabel CMU Panoptic sequences: one head-pose label per face per camera.

    Each SEQ_DIR holds calibration_<seq>.json and hdFace3d/faceRecon3D_hd*.json
    or the downloaded hdFace3d.tar (read in place; frames are found by
    number; gaps are fine), or is a folder whose sub-folders are sequences. For each face, WHENet's
    58-point reference head is fitted to its 14 landmark pairs with
    confidence > 0.1 (at least 7 pairs needed); fits with RMSE above
    --max-rmse are rejected. Each HD camera then gets the label
    A = E @ R_cam @ R_head (E = diag(1, -1, -1)), the helmet box (correct
    OpenCV distortion) and the 70 landmarks projected to 2-D.

    The table has sequence, frame, camera, person_id, image
    (hdImgs/<cam>/<cam>_<frame>.jpg), bbox_x/y/w/h (pixels), the columns of
    `hpe convert` (pitch, yaw, roll, pitch_2.., r00..r22, gimbal_lock,
    roundtrip_err), fit_rmse (cm), n_pairs, scale, image_width,
    image_height and lm0_x..lm69_y. Every face/camera that gets no label is
    listed by --rejects with its reason (bad landmarks, too few confident
    points, bad fit, behind camera, outside image, box rejected, dropped by
    legacy rule, not seen by every camera, below --min-change, skipped by
    --every, truncated face file) and counted in the summary, per sequence
    and in total: labels + rejects = every view of the frames in --frames.
    The frames --every skips are read (not fitted) to list their views.
    --strict fails on any reject except those of the sampling rules asked
    for (--every, --min-change, --all-views).
    With several sequences, one that cannot be read (its calibration, a
    face file, no face files) fails the run with an error naming the file;
    no dataset is written without it. --frame crop
    labels relative to the line of sight and adds ray_angle. --format whenet and coco name the whole frame's
    image: crop it with the box.

    \b
    Examples:
      hpe relabel-panoptic sample_data/panoptic_160906_pizza1 -o labels.parquet
      hpe relabel-panoptic SEQ -o labels.csv --cameras 00_00,00_08 --frames 1000:2000 --every 10
      hpe relabel-panoptic SEQ -o train.json --format coco --preset directmhp --workers 2
      hpe relabel-panoptic SEQ -o annotation.txt --format whenet --legacy-whenet --max-rmse inf
      hpe relabel-panoptic SEQ -o labels.parquet --system 6drepnet --rejects rejects.csv
      hpe relabel-panoptic ROOT/seqA ROOT/seqB -o labels.parquet --no-landmarks --workers 2
      hpe relabel-panoptic ROOT -o labels.parquet --frame crop --cameras whenet-haggling --min-change 5
      hpe relabel-panoptic ROOT -o labels.parquet --scheduler tcp://head:8786 --resume
    """
    from ..pipelines.relabel import FormatSystemError, RelabelPanopticOptions, run_relabel_panoptic

    try:
        opts = RelabelPanopticOptions(
            system=system,
            fmt=fmt or format_from_suffix(output),
            preset=preset,
            calibration=calibration,
            cameras=cameras,
            every=every,
            frames=frame_range,
            min_change=min_change,
            all_views=all_views,
            frame=label_frame,
            landmarks=not no_landmarks,
            max_rmse=max_rmse,
            legacy=legacy_whenet,
            workers=workers,
            scheduler=scheduler,
            resume=resume,
            rejects=rejects,
            strict=strict,
            overwrite=overwrite,
        )
    except FormatSystemError as exc:
        raise click.UsageError(str(exc)) from None
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--frames") from None
    bar = lambda total: progress(total=total, desc="relabel-panoptic", quiet=quiet, unit="frames")  # noqa: E731
    done = run_relabel_panoptic(seq_dirs, output, opts, progress=bar)
    if verbose:
        for line in done.plan_lines():
            echo_summary([line], quiet)
    echo_summary(done.summary(), quiet)
