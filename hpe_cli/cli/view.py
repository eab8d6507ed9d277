"""``hpe view``: a browsable offline page of every row of a label table (and of a second one beside it)."""

from __future__ import annotations

import click

from .options import (
    SYSTEM,
    SYSTEMS,
    columns_option,
    echo_summary,
    file_system_option,
    images_option,
    output_folder_option,
    overwrite_option,
    progress,
    radians_option,
    rejects_options,
    threads_option,
    verbosity_options,
)
from .table_options import column_options


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("labels", type=click.Path(exists=True))
@click.argument("other", type=click.Path(exists=True), required=False)
@output_folder_option(
    "Page folder (created if missing): index.html, rows.js, thumbs/, frames/; open index.html in a browser."
)
@images_option("Folder the `image` column is relative to (default: LABELS' folder).")
@file_system_option("Rotation system of LABELS, and of the angles the page shows and filters")
@click.option(
    "--other-system",
    "other_system",
    type=SYSTEM,
    default=None,
    help="Rotation system of OTHER [default: its own, else --system].",
)
@click.option(
    "--also-in",
    "also_in",
    type=SYSTEMS,
    default=None,
    metavar="SYSTEM[,SYSTEM...]",
    help="Also give every row's angles in these systems: the page's angle filters, sort and coverage map then "
    "work in any of them (a selector; default: LABELS' system).",
)
@radians_option()
@columns_option("Read pitch,yaw,roll or r00..r22 (auto: the system's own columns, then angles, then matrices).")
@click.option(
    "--key",
    "keys",
    metavar="COL[,COL...]",
    callback=lambda ctx, p, v: [k.strip() for k in v.split(",") if k.strip()] if v else None,
    help="Columns joining OTHER's rows to LABELS' rows [default: image (or file), with person_id when both "
    "tables have it].",
)
@click.option("--title", help="Page title [default: LABELS' file name].")
@threads_option
@click.option(
    "--frames/--no-frames",
    default=True,
    show_default=True,
    help="Make each image once at 960 px for the detail view (--no-frames: the detail view shows the "
    "thumbnail; for many distinct images).",
)
@rejects_options
@overwrite_option
@verbosity_options
@column_options
def view(
    labels,
    other,
    outdir,
    images,
    system,
    other_system,
    also_in,
    radians,
    use,
    keys,
    title,
    threads,
    frames,
    rejects,
    strict,
    overwrite,
    verbose,
    quiet,
):
    """Write a page that shows every face of LABELS with its pose, offline.

    The page (OUTDIR/index.html) opens from disk in any browser, with no
    server and nothing loaded from the network: a grid of thumbnails (the
    crop around the head box with the pose drawn on it, the whole frame for
    rows without a box), filters on pitch, yaw and roll (in the labels'
    system, or in any system named by --also-in) and on every category, flag and number column, sorting by any
    column, a yaw-pitch coverage map whose cells filter the grid, and a click
    on a face shows its whole frame with the head box, the landmarks, the
    pose(s), every column and the file and line (or row) it came from. The
    filters are kept in the page's address, so a view can be shared.

    With OTHER (a second label table of the same images: a legacy relabel,
    predictions, another convention), rows are joined by key as `hpe
    evaluate` joins them; each face shows both poses, LABELS solid and OTHER
    dashed, and the angle between them (the geodesic distance `hpe evaluate`
    reports), which the grid can filter and sort by.

    Thumbnails are named by their content: running again into the same folder
    (with --overwrite) makes only the pictures of new or changed rows. Rows
    whose image is missing or unreadable, and rows of OTHER that match no
    row of LABELS, go to --rejects (without it they are an error).

    \b
    Examples:
      hpe view AFLW2000/ -o aflw_page/
      hpe view labels.parquet -o page/ --images frames/
      hpe view corrected.parquet legacy.parquet -o compare/ --images panoptic/ --rejects missing.csv
      hpe view gt.csv preds.csv -o errors/ --other-system 6drepnet --key image
      hpe view panoptic_whenet.parquet -o page/ --images panoptic/ --also-in 300w_lp,3ddfa_v2
      hpe view labels.parquet -o page/ --overwrite   # after the table grew: reuses the thumbnails
    """
    from ..pipelines.view import ViewOptions, run_view

    options = ViewOptions(
        images=images,
        system=system,
        other_system=other_system,
        also_in=also_in,
        radians=radians,
        use=use,
        keys=keys,
        threads=threads,
        title=title,
        frames=frames,
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
    )
    bar = progress(desc="view", quiet=quiet, unit="faces")
    try:
        s = run_view(labels, outdir, other, options, progress=bar)
    finally:
        bar.close()
    lines = [
        f"{s['shown']} of {s['rows']} rows shown ({s['made']} thumbnails made, {s['reused']} reused; "
        f"{s['whole_frame']} without a head box shown whole) from {s['images']} images -> {outdir}/index.html"
    ]
    if s.get("pruned"):
        lines.append(f"{s['pruned']} files of the earlier page no longer used: removed")
    if other is not None:
        lines.append(f"{s['matched']} rows paired with {other} by {', '.join(s['keys'])}")
    lines += s["notes"]
    if s["rejects"]:
        lines.append(
            "rejected: "
            + "; ".join(f"{n} {r}" for r, n in s["rejects"].items())
            + (f" -> {rejects}" if rejects else "")
        )
    echo_summary(lines, quiet)
