"""``hpe relabel-panoptic``: head-pose labels from CMU Panoptic 3-D face landmarks."""
from __future__ import annotations

import click

from .options import (SYSTEM, non_negative_or_inf, format_from_suffix, echo_summary, output_option, overwrite_option, progress, rejects_options,
                      verbosity_options)

FORMATS = ("table", "coco", "whenet")


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("seq_dir", type=click.Path(exists=True, file_okay=False))
@output_option(help="Output: a .parquet/.csv table, or with --format coco a .json, with --format whenet a .txt.")
@click.option("--calibration", type=click.Path(exists=True, dir_okay=False),
              help="Calibration JSON [default: SEQ_DIR/calibration_<seq>.json].")
@click.option("--system", "system", type=SYSTEM, default=None,
              help="Rotation system of the labels: built-in name or .toml file "
                   "[default: 300w_lp; whenet for --format coco/whenet, which store WHENet's angles].")
@click.option("--preset", type=click.Choice(["whenet", "directmhp"]), default="whenet", show_default=True,
              help="Helmet radius and box rule: whenet (radius 22, aspect <= 2) or directmhp (radius 18, "
                   "aspect < 1.5, each side < 70% of the image).")
@click.option("--format", "fmt", type=click.Choice(FORMATS), default=None,
              help="table (Parquet/CSV), coco (DirectMHP's COCO JSON) or whenet (annotation.txt lines) "
                   "[default: from OUTPUT's extension].")
@click.option("--cameras", default="hd", show_default=True,
              help="hd, or comma-separated camera names such as 00_00,00_08.")
@click.option("--every", type=click.IntRange(1), default=1, show_default=True,
              help="Frame step: keep frame numbers start, start+N, ... (looked up by number).")
@click.option("--frames", "frame_range", default=None, metavar="A:B",
              help="Only frames A <= frame < B (either side may be empty).")
@click.option("--workers", type=click.IntRange(1), default=1, show_default=True,
              help="Worker processes (chunks of 64 frames each).")
@click.option("--max-rmse", type=float, default=None, callback=non_negative_or_inf, metavar="X",
              help="Reject faces whose fit RMSE is above X (cm). 'inf' labels every fit, as WHENet did. "
                   "[default: 2.0: consistent faces of 160906_pizza1 fit to 0.6-1.3 cm, broken ones "
                   "to 2.8-6.7 cm]")
@click.option("--legacy-whenet", is_flag=True,
              help="Label with WHENet's own chain (compound, Z-Y-X decomposition, select_euler, negation) "
                   "and drop what it drops; adds legacy_pitch/yaw/roll columns.")
@rejects_options
@overwrite_option
@verbosity_options
def relabel_panoptic(seq_dir, output, calibration, system, preset, fmt, cameras, every, frame_range, workers,
                     max_rmse, legacy_whenet, rejects, strict, overwrite, verbose, quiet):
    """Relabel a CMU Panoptic sequence: one head-pose label per face per camera.

    SEQ_DIR holds calibration_<seq>.json and hdFace3d/faceRecon3D_hd*.json
    (frames are found by number; gaps are fine). For each face, WHENet's
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
    listed by --rejects with its reason (too few confident points, bad fit,
    behind camera, outside image, box rejected, dropped by legacy rule) and
    counted in the summary. --format whenet and coco name the whole frame's
    image: crop it with the box.

    \b
    Examples:
      hpe relabel-panoptic sample_data/panoptic_160906_pizza1 -o labels.parquet
      hpe relabel-panoptic SEQ -o labels.csv --cameras 00_00,00_08 --frames 1000:2000 --every 10
      hpe relabel-panoptic SEQ -o train.json --format coco --preset directmhp --workers 2
      hpe relabel-panoptic SEQ -o annotation.txt --format whenet --legacy-whenet --max-rmse inf
      hpe relabel-panoptic SEQ -o labels.parquet --system 6drepnet --rejects rejects.csv
    """
    from ..pipelines import panoptic as job
    from ..pipelines.relabel import DEFAULT_MAX_RMSE

    fmt = fmt or format_from_suffix(output)
    if fmt != "table" and system is not None and system.name != "whenet":
        raise click.UsageError(f"--format {fmt} stores WHENet/DirectMHP angles, which are in the whenet system; "
                               f"got --system {system.name} (use --format table for other systems)")
    system = system or SYSTEM.convert("whenet" if fmt != "table" else "300w_lp", None, None)
    try:
        frames = job.parse_frames(frame_range)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--frames") from None
    max_rmse = DEFAULT_MAX_RMSE if max_rmse is None else max_rmse
    plan = job.plan(seq_dir, calibration, cameras, every, frames)
    cfg = job.Config(system=system, preset=preset, max_rmse=max_rmse, legacy=legacy_whenet)
    if verbose:
        echo_summary([f"calibration: {plan.calibration} ({len(plan.cameras)} cameras: "
                      f"{', '.join(plan.cameras.names[:6])}{' ...' if len(plan.cameras) > 6 else ''})",
                      f"frames: {len(plan.frames)} selected of {plan.available} face files, "
                      f"{len(plan.chunks)} chunks"], quiet)
    bar = progress(total=len(plan.frames), desc="relabel-panoptic", quiet=quiet, unit="frames")
    try:
        stats = job.write_outputs(plan, cfg, output, fmt, rejects, overwrite, workers, bar)
    finally:
        bar.close()
    if strict:  # any face/view not labelled fails the run (nothing is committed)
        from ..io.rejects import rejects_rule

        first = next(iter(getattr(stats, "reasons", None) or getattr(stats, "face_reasons", None) or
                          getattr(stats, "view_reasons", {})), None)
        rejects_rule(sum(stats.view_reasons.values()) + sum(stats.face_reasons.values()), first, has_file=True,
                     strict=True)
    echo_summary(stats.summary(plan, cfg, output, rejects), quiet)
