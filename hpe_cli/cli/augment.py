"""``hpe augment``: rotate or mirror a labelled dataset (labels, landmarks, boxes, images)."""

from __future__ import annotations

import os

import click

from ..io.images import IMAGE_COLUMNS
from .choices import RegistryChoice
from .options import (
    batch_option,
    deprecated_spellings,
    echo_summary,
    file_system_option,
    image_size_option,
    output_option,
    overwrite_option,
    progress,
    radians_option,
    rejects_options,
    threads_option,
    verbosity_options,
)
from .table_options import column_options


@deprecated_spellings("image-size")
@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@output_option()
@file_system_option("Rotation system of the labels and of OUTPUT: a built-in name or a .toml file")
@image_size_option(
    help="Width and height of the images, in pixels, as WxH. Optional when the table has "
    "image_width/image_height or --images is given; a row where these disagree is rejected."
)
@radians_option()
@click.option("--hflip", is_flag=True, help="Mirror left-right (with --vflip: both, a rotation by 180).")
@click.option("--vflip", is_flag=True, help="Mirror top-bottom.")
@click.option(
    "--rotate",
    type=float,
    metavar="DEG",
    help="Rotate counter-clockwise on screen by DEG degrees about the image centre (OpenCV's sign).",
)
@click.option(
    "--mirror-line",
    type=float,
    metavar="DEG",
    help="Mirror about the line through the image centre at DEG degrees counter-clockwise from the "
    "horizontal (90 = --hflip, 0 = --vflip).",
)
@click.option(
    "--crop",
    nargs=4,
    type=float,
    default=None,
    metavar="X Y W H",
    help="Cut the W x H rectangle whose top-left pixel is (X, Y) (whole pixels); labels keep their "
    "rotation, every position moves by (-X, -Y).",
)
@click.option(
    "--scale",
    "zoom",
    type=click.FloatRange(0, min_open=True),
    default=None,
    metavar="S",
    help="Resize by S (W*S and H*S must be whole pixels): positions scale about the image's top-left "
    "edge as cv2.resize maps them; size and Pose_Para scale multiply by S.",
)
@click.option(
    "--landmarks",
    "scheme",
    type=RegistryChoice("hpe_cli.geometry.landmark_schemes:SCHEMES", first=("auto",), extra=("none",)),
    default="auto",
    show_default=True,
    help="Left/right scheme of the lm{i}_x/lm{i}_y columns, re-indexed after a mirror. auto: by count "
    "(68, 70, 21). none: leave the landmark columns unchanged.",
)
@click.option(
    "--box-from",
    type=click.Choice(["auto", "landmarks", "corners"]),
    default="auto",
    show_default=True,
    help="New box: the moved corners (exact for flips and 90-degree turns), or the box of the moved "
    "landmarks. auto: corners when exact, else landmarks, else corners.",
)
@click.option("--clip", is_flag=True, help="Clip boxes to the pixel centres [0, W-1] x [0, H-1].")
@click.option(
    "--images",
    "images_dir",
    type=click.Path(exists=True, file_okay=False),
    help="Folder of the input images (names from the image column, relative to it; default for a "
    ".mat folder: the folder); alone, it gives each row's image size.",
)
@click.option(
    "--out-images",
    "out_images",
    type=click.Path(file_okay=False),
    help="Folder for the transformed images (same relative names); created if missing.",
)
@click.option(
    "--image-column",
    help=f"Column with image file names. Default: the first of {', '.join(IMAGE_COLUMNS)}; "
    "a .mat name is matched to the image with the same stem.",
)
@click.option(
    "--interpolation",
    type=click.Choice(["linear", "cubic", "nearest", "area", "lanczos"]),
    default="linear",
    show_default=True,
    help="Resampling for rotations and oblique mirrors.",
)
@click.option(
    "--border",
    type=click.Choice(["constant", "replicate", "reflect", "reflect101", "wrap"]),
    default="constant",
    show_default=True,
    help="Fill of pixels that come from outside the image.",
)
@click.option("--jpeg-quality", type=click.IntRange(1, 100), default=95, show_default=True)
@rejects_options
@overwrite_option
@batch_option
@threads_option
@verbosity_options
@column_options
def augment(
    input,
    output,
    system,
    image_size,
    radians,
    hflip,
    vflip,
    rotate,
    mirror_line,
    crop,
    zoom,
    scheme,
    box_from,
    clip,
    images_dir,
    out_images,
    image_column,
    interpolation,
    border,
    jpeg_quality,
    rejects,
    strict,
    overwrite,
    batch_size,
    threads,
    verbose,
    quiet,
):
    """Rotate, mirror, crop or resize a head-pose dataset: labels, landmarks, boxes and images.

    INPUT is a .parquet/.csv label table (or a folder of .mat files) with
    angle columns pitch,yaw,roll (degrees) or, when it has none, matrix
    columns r00..r22 (the stored matrix of --system); rows where both are
    present and disagree are rejected. Labels are moved
    exactly: A' = M A for a rotation, A' = M A diag(-1,1,1) for a
    mirror, in the canonical frame, then written back in --system with both
    Euler solutions, the matrix, gimbal_lock and roundtrip_err.

    Landmarks lm{i}_x, lm{i}_y move with the image and, after a mirror, are
    re-indexed with the scheme's left/right permutation (index 36 stays the
    subject's right outer eye corner). Boxes bbox_x, bbox_y, bbox_w, bbox_h
    move too. Every other column passes through unchanged.

    Pixel convention: pixel (u, v) has its centre at integer coordinates
    (OpenCV's); --hflip maps x to W-1-x and --rotate turns about
    ((W-1)/2, (H-1)/2), exactly like cv2.flip and
    cv2.warpAffine(getRotationMatrix2D(((W-1)/2, (H-1)/2), DEG, 1)).
    A crop or a resize keeps the labels' rotation (the 300W-LP model is
    orthographic) and moves every position; a resize also multiplies the
    lengths (size, Pose_Para scale). Images keep their size (--crop: W x H,
    --scale: W*S x H*S); rotated corners are filled per
    --border. tdx, tdy move too (from the bottom row for Pose_Para tables);
    image_width/image_height become the output size.

    Image sizes come from the images (--images), the image_width/image_height
    columns or --image-size; a row where two of them disagree is rejected
    (never transformed with the wrong centre). A .mat folder augmented with
    --out-images gets its .mat files written back beside the images:
    Pose_Para (angles, tdx, tdy), pt2d and pt3d_68 moved (re-indexed after a
    mirror), roi cut to the crop. The images are committed with the table as
    a whole; two rows whose different images would be written to one output
    name are an error naming both; a run where every row is rejected exits 1.

    \b
    Examples:
      hpe augment labels.csv -o flipped.csv --image-size 450x450 --hflip   # a table without image sizes
      hpe augment labels.csv -o rot30.csv --system 6drepnet --image-size 640x480 --rotate 30
      hpe augment AFLW2000/ -o rot.parquet --image-size 450x450 --rotate -15 --images AFLW2000/ --out-images rot/
      hpe augment aflw_lm.parquet -o aflw_v.parquet --image-size 450x450 --vflip --landmarks aflw21
      hpe augment labels.parquet -o m20.parquet --image-size 450x450 --mirror-line 20 --clip
      hpe augment labels.parquet -o both.parquet --image-size 450x450 --hflip --vflip
      hpe augment out/labels.parquet -o flipped.parquet --hflip   # sizes from image_width/image_height
      hpe augment AFLW2000/ -o c.parquet --crop 50 50 350 350 --images AFLW2000/ --out-images c/   # + .mat files
      hpe augment labels.parquet -o half.parquet --scale 0.5 --images frames/ --out-images half/
    """
    chosen = [
        name
        for name, on in (
            ("--hflip", hflip),
            ("--vflip", vflip),
            ("--rotate", rotate is not None),
            ("--mirror-line", mirror_line is not None),
            ("--crop", crop is not None),
            ("--scale", zoom is not None),
        )
        if on
    ]
    if not chosen:
        raise click.UsageError(
            "expected one of --hflip, --vflip, --rotate DEG, --mirror-line DEG, --crop X Y W H, --scale S; got none"
        )
    if len(chosen) > 1 and sorted(chosen) != ["--hflip", "--vflip"]:
        raise click.UsageError(f"expected one augmentation (or --hflip with --vflip), got {' and '.join(chosen)}")
    if hflip and vflip:
        op, angle = "hvflip", None
    elif hflip or vflip:
        op, angle = ("hflip" if hflip else "vflip"), None
    elif rotate is not None:
        op, angle = "rotate", rotate
    elif crop is not None:
        if any(v != int(v) for v in crop) or crop[2] < 1 or crop[3] < 1:
            raise click.BadParameter(
                f"expected whole pixels and W, H >= 1, got {' '.join(f'{v:g}' for v in crop)}", param_hint="--crop"
            )
        crop = tuple(int(v) for v in crop)
        op, angle = "crop", None
    elif zoom is not None:
        op, angle = "scale", None
    else:
        op, angle = "mirror", mirror_line
    for name, v in (("--rotate", rotate), ("--mirror-line", mirror_line)):
        if v is not None and not abs(v) < float("inf"):
            raise click.BadParameter(f"expected a finite angle in degrees, got {v}", param_hint=name)
    if images_dir is None and out_images is not None and not os.path.isdir(input):
        raise click.UsageError("--out-images needs --images (the folder of the input images)")
    from ..pipelines.augment import AugmentOptions, run_augment

    opts = AugmentOptions(
        op=op,
        angle=angle,
        crop=crop,
        scale=zoom,
        image_size=tuple(image_size) if image_size else None,
        system=system,
        radians=radians,
        scheme=scheme,
        box_from=box_from,
        clip=clip,
        images_dir=images_dir,
        out_images=out_images,
        image_column=image_column,
        interpolation=interpolation,
        border=border,
        jpeg_quality=jpeg_quality,
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        batch_size=batch_size,
        verbose=verbose,
        threads=threads,
    )
    desc = opts.description
    bar = progress(desc="augment", quiet=quiet)
    try:
        s = run_augment(input, output, opts, bar=bar)
    finally:
        bar.close()
    lines = [
        f"{s['written']} of {s['rows']} rows augmented ({desc}) in {s['system']} -> {output}",
        f"landmarks: {s['landmarks']}; boxes: {s['boxes']}",
    ]
    if verbose:
        lines.append(
            f"labels read from {s['label_source']}; pixel centres at integers, image centre "
            + (
                f"({(image_size[0] - 1) / 2:g}, {(image_size[1] - 1) / 2:g})"
                if image_size
                else "((W-1)/2, (H-1)/2) of each image"
            )
        )
    if out_images is not None:
        lines.append(
            f"images: {s['images']} written -> {out_images}"
            + (f"; {s['mats']} .mat files written back beside them" if s.get("mats") else "")
        )
    if s["rejects"]:
        from collections import Counter

        kinds = Counter()  # "image not found: PATH" -> "image not found" (the file keeps each row's reason)
        for r, n in s["rejects"].items():
            kinds[r.split(": ", 1)[0]] += n
        lines.append(
            "rejected: "
            + "; ".join(f"{n} {r}" for r, n in kinds.most_common())
            + (f" -> {rejects}" if rejects else " (use --rejects FILE to keep them)")
        )
    echo_summary(lines, quiet)
