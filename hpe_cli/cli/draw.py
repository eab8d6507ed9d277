"""``hpe draw``: draw pose axes or a pose cube onto images (or blank canvases)."""

from __future__ import annotations

import click

from .options import (
    columns_option,
    deprecated_spellings,
    echo_summary,
    file_system_option,
    image_size_option,
    images_option,
    output_folder_option,
    overwrite_option,
    progress,
    radians_option,  # the one spelling of input angle units
    rejects_options,
    threads_option,
    verbosity_options,
)
from .table_options import column_options


@deprecated_spellings("canvas", "image-size")
@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@output_folder_option("Output folder (created if missing); images keep their relative names.")
@images_option("Folder the `image` column is relative to (default: INPUT's folder).")
@file_system_option()
@click.option(
    "--style",
    type=click.Choice(["axes", "cube"]),
    default="axes",
    show_default=True,
    help="Three axis lines (Hopenet's draw_axis) or the pose cube.",
)
@image_size_option(
    "canvas",
    help="Draw on blank canvases of this size (WxH, e.g. 640x480) instead of reading "
    "images. The old --canvas WxH still works, with a warning.",
)
@radians_option()
@columns_option("Draw from pitch,yaw,roll or r00..r22 (auto: angles when present).")
@click.option(
    "--length",
    type=click.FloatRange(0, min_open=True),
    help="Line length in pixels for every face (overrides bbox_h/2, size and scale).",
)
@click.option("--thickness", type=click.IntRange(1, 50), help="Line thickness in pixels (default: from the length).")
@click.option(
    "--tdy-origin",
    type=click.Choice(["auto", "top", "bottom"]),
    default="auto",
    show_default=True,
    help="tdy is measured from the image top (pixel row) or from the bottom row (300W-LP Pose_Para: "
    "row = height - 1 - tdy). auto: bottom for .mat input or tables with tdz and scale columns.",
)
@click.option("--annotate", is_flag=True, help="Write the angles (in --system) above each face.")
@click.option("--grid", is_flag=True, help="Write contact sheets (contact_sheet_001.png, ...) instead of images.")
@click.option(
    "--grid-cols",
    type=click.IntRange(1, 64),
    default=6,
    show_default=True,
    help="Tiles per row (a sheet holds cols x cols tiles).",
)
@click.option("--tile", type=click.IntRange(32, 2048), default=256, show_default=True, help="Tile size, pixels.")
@click.option("--limit", type=click.IntRange(1), help="Draw at most this many images.")
@click.option(
    "--worst",
    type=click.IntRange(1),
    metavar="N",
    help="With `hpe evaluate -o` output: draw only the N rows with the largest --sort-by error.",
)
@click.option(
    "--sort-by",
    "sort_by",
    metavar="COLUMN",
    help="With `hpe evaluate -o` output: the error column to rank rows by, largest first [default: geodesic].",
)
@rejects_options
@overwrite_option
@threads_option
@verbosity_options
@column_options
def draw(
    input,
    outdir,
    images,
    system,
    style,
    canvas,
    radians,
    use,
    length,
    thickness,
    tdy_origin,
    annotate,
    grid,
    grid_cols,
    tile,
    limit,
    worst,
    sort_by,
    rejects,
    strict,
    overwrite,
    threads,
    verbose,
    quiet,
):
    """Draw head poses onto their images.

    INPUT is a .parquet or .csv label table (angles pitch,yaw,roll in degrees,
    or matrices r00..r22 in --system) with an `image` column, or a folder of
    300W-LP/AFLW2000 .mat files (image = the same name with .jpg). Each image
    is drawn once with all its rows and written to OUTDIR under the same
    relative name.

    The drawing uses only the matrix, mapped to the canonical 300W-LP frame,
    so it is right for every system and for yaw beyond +-90. Lines start at
    the head centre: red (BGR 0,0,255) points to the subject's left, green
    (0,255,0) from forehead to chin, blue (255,0,0) out of the nose. The cube
    has a red back square, blue edges along the nose and a green face-front
    square; hidden edges are dashed, so a face turned away shows its green
    square dashed behind the red one.

    INPUT may also be the per-row output of `hpe evaluate -o` (columns
    gt_pitch..pred_roll, system from its metadata): each of its rows (or the
    --worst N by --sort-by) becomes one PNG, <rank>_<image>.png, with the
    ground truth solid and the prediction dashed (dots at the ends) on the same
    face, a legend top-left and the error top-right.

    Rows naming the same image are drawn together on it; two different images
    that would be written to one output name are an error naming both rows.
    A run that draws nothing because every row was rejected exits 1.

    \b
    Centre and length, per row (first that is present):
      bbox_x,bbox_y,bbox_w,bbox_h  centre of the box, length bbox_h/2
      tdx,tdy[,size]               centre (tdx, tdy), length `size`;
                                   with tdz,scale (Pose_Para) length
                                   100000*scale and tdy from the bottom
      nothing                      image centre, length min(W,H)/4

    \b
    Examples:
      hpe draw AFLW2000/ -o drawn/
      hpe draw labels.parquet -o drawn/ --images AFLW2000/ --style cube
      hpe draw preds.csv -o drawn/ --images frames/ --system 6drepnet --columns matrix
      hpe draw poses.csv -o canvas/ --image-size 640x480 --annotate
      hpe draw AFLW2000/ -o sheet/ --grid --grid-cols 4 --annotate
      hpe draw errors.parquet -o worst/ --images AFLW2000/ --worst 20 --sort-by geodesic
      hpe draw errors.parquet -o worst/ --images frames/ --worst 20 --rejects missing.csv
    """
    from ..pipelines.draw import DrawOptions, run_draw

    options = DrawOptions(
        images=images,
        system=system,
        style=style,
        canvas=canvas,
        radians=radians,
        use=use,
        length=length,
        thickness=thickness,
        tdy_origin=tdy_origin,
        annotate=annotate,
        grid=grid,
        grid_cols=grid_cols,
        tile=tile,
        limit=limit,
        worst=worst,
        sort_by=sort_by,
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        threads=threads,
    )
    bar = progress(desc="draw", quiet=quiet, unit="images")
    try:
        s = run_draw(input, outdir, options, progress=bar)
    finally:
        bar.close()
    if "drawn" in s:
        lines = [
            (
                f"drew ground truth (solid) and prediction (dashed) of {s['faces']} rows, worst "
                f"{sort_by or 'geodesic'} first, angles in {s['system']} ({s['system_source']}) -> {outdir}"
            )
        ]
        if s["rejects"]:
            lines.append("rejected: " + "; ".join(f"{n} {r}" for r, n in s["rejects"].items()) + f" -> {rejects}")
        echo_summary(lines, quiet)
        return
    lines = [
        f"drew {s['faces']} faces ({style}) on {s['images']} {'canvases' if canvas else 'images'} -> "
        + (f"{s['sheets']} contact sheet(s) in {outdir}" if grid else str(outdir))
    ]
    if s["rejects"]:
        lines.append(
            "rejected: "
            + "; ".join(f"{n} {r}" for r, n in s["rejects"].items())
            + (f" -> {rejects}" if rejects else "")
        )
    echo_summary(lines, quiet)
