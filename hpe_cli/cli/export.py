"""``hpe export``: training-ready datasets in the exact layout each trainer reads."""

from __future__ import annotations

import click

from .choices import RegistryChoice
from .options import (
    SYSTEM,
    echo_summary,
    exclude_option,
    overwrite_option,
    progress,
    radians_option,
    rejects_options,
    resume_option,
    scheduler_option,
    verbosity_options,
)
from .table_options import column_options


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("labels", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("-o", "--output", "output", required=True, type=click.Path(), help="Output folder (OUT_DIR).")
@click.option(
    "--layout",
    required=True,
    type=RegistryChoice("hpe_cli.io.export:LAYOUTS"),
    help="whenet (crops + annotation.txt), 6drepnet (images + .mat + file list of stems; --form crops: "
    "crops + list), directmhp (frames, COCO JSON, YOLO labels, data.yaml; needs a train and a val "
    "split), fsanet (.npz), hf (Parquet + dataset card).",
)
@click.option(
    "--form",
    type=RegistryChoice("hpe_cli.io.export:LAYOUTS", attribute="forms"),
    default=None,
    help="6drepnet only: mat (default; <split>/<stem>.jpg + <stem>.mat + files.txt of stems, what the "
    "Pose_300W_LP/AFLW2000 classes of 6DRepNet, 6DRepNet360 and Hopenet read), or crops "
    "(256 x 256 crops + files_<split>.txt 'name.jpg pitch yaw roll', DirectMHP's 6DRepNet fork).",
)
@click.option(
    "--trainer",
    type=RegistryChoice("hpe_cli.io.export:LAYOUTS", attribute="trainers"),
    default=None,
    help="6drepnet only: whose range rule applies. hopenet: every angle in [-99, 99) (its 66 bins); "
    "6drepnet: |angle| <= 99 (its create_filename_list.py; its training class itself reads any "
    "angle); 6drepnet360: full range [default: 6drepnet with --form mat, no rule with --form crops].",
)
@click.option(
    "--images",
    multiple=True,
    type=click.Path(exists=True, file_okay=False),
    help="Where image paths resolve (once for all inputs, or once per input) "
    "[default: each table's folder; a .mat folder itself].",
)
@click.option(
    "--system",
    "system",
    type=SYSTEM,
    default=None,
    help="Label system of the hf layout [default: 300w_lp]; the other layouts fix their trainer's.",
)
@click.option(
    "--from",
    "input_system",
    type=SYSTEM,
    default=None,
    help="System of the input tables' angles [default: the table's hpe:system metadata, else 300w_lp].",
)
@radians_option()
@click.option(
    "--crop-scale",
    type=click.FloatRange(0, min_open=True),
    default=None,
    help="Enlarge each head box by this factor about its centre [default: 1].",
)
@click.option(
    "--square/--no-square",
    default=None,
    help="Square crops (side = the box's longer side) [default: square for fsanet].",
)
@click.option(
    "--size",
    type=click.IntRange(1),
    default=None,
    help="Resize crops to SIZE (SIZE x SIZE when square, else width SIZE) [default: none; 64 for fsanet].",
)
@click.option("--quality", type=click.IntRange(1, 100), default=95, show_default=True, help="JPEG quality.")
@click.option(
    "--pad-value",
    type=click.IntRange(0, 255),
    default=0,
    show_default=True,
    help="Constant for the parts of a crop outside the frame.",
)
@click.option(
    "--min-inside",
    type=click.FloatRange(0, 1),
    default=0.5,
    show_default=True,
    help="Reject a head whose box is less than this fraction inside the image.",
)
@click.option(
    "--split",
    "split",
    default=None,
    metavar="COL:FRACTIONS",
    help="Group split, e.g. sequence:0.8,0.2 or subject:train=0.7,val=0.1,test=0.2 "
    "(COL: sequence, subject, identity = 300W-LP NAME of NAME_k, person_id, camera, source).",
)
@click.option(
    "--split-file",
    type=click.Path(exists=True, dir_okay=False),
    help="Explicit split: a CSV with a group column (e.g. sequence) and split.",
)
@exclude_option
@click.option(
    "--min-change",
    type=click.FloatRange(0),
    default=None,
    metavar="DEG",
    help="Per (sequence, person, camera): keep a sample only if it turned more than DEG degrees "
    "(geodesic) from the last kept one.",
)
@click.option("--balance", default=None, metavar="yaw:BIN:MAX", help="At most MAX samples per BIN-degree yaw bin.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for --balance and --split.")
@click.option(
    "--drop-images-with-rejects",
    is_flag=True,
    help="Drop a whole image when any head in it is rejected (DirectMHP's rule).",
)
@click.option(
    "--workers",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="Worker processes; each makes the crops of units of one video x 256 frames (or 64 images).",
)
@scheduler_option
@resume_option("label tables, the split file, images and videos are compared by size, modification time and inode")
@column_options
@rejects_options
@overwrite_option
@verbosity_options
def export(
    labels,
    output,
    layout,
    form,
    trainer,
    images,
    system,
    input_system,
    radians,
    crop_scale,
    square,
    size,
    quality,
    pad_value,
    min_inside,
    split,
    split_file,
    exclude,
    min_change,
    balance,
    seed,
    drop_images_with_rejects,
    workers,
    scheduler,
    resume,
    rejects,
    strict,
    overwrite,
    verbose,
    quiet,
):
    """Export labels as a training-ready dataset in a trainer's own layout.

    LABELS: tables with an image reference and a head box (hpe relabel-panoptic/relabel-agora output, or any
    .parquet/.csv with image, bbox_x/y/w/h and labels), or 300W-LP/AFLW2000 .mat folders (box from the
    visible landmarks, with 6DRepNet's AFLW2000 margin). Several inputs are merged (a source column tells
    them apart). Labels go to each layout's system through the rotation matrices; every label not exported
    is in --rejects with its reason. Bad input (unusable rows, missing or unreadable images, boxes outside the
    frame) needs --rejects FILE, else nothing is written; the layout's own rules, the sampling and the split
    file only remove labels (counted in the summary; --strict makes any removal an error). OUT_DIR is
    written in a staging folder and committed at the end.

    \b
    Examples:
      hpe export pizza.parquet -o out/whenet --layout whenet --images SEQ --rejects rej.csv
      hpe export a.parquet b.parquet -o out/dmhp --layout directmhp --drop-images-with-rejects --rejects rej.csv
      hpe export AFLW2000/ -o out/aflw --layout 6drepnet
      hpe export pizza.parquet -o out/360 --layout 6drepnet --trainer 6drepnet360 --images SEQ --rejects rej.csv
      hpe export 300W_LP/ -o out/hopenet --layout 6drepnet --trainer hopenet
      hpe export pizza.parquet -o out/dmhp --layout directmhp --split camera:train=0.75,val=0.25 --images SEQ
      hpe export AFLW2000/ 300W_LP/AFW -o out/fsa --layout fsanet --split identity:0.9,0.1
      hpe export pizza.parquet -o out/hf --layout hf --system 6drepnet --min-change 5 --balance yaw:10:500
      hpe export preds_rad.csv -o out/hf --layout hf --from 6drepnet --radians --rejects rej.csv
      hpe export labels.parquet -o out/whenet --layout whenet --images ROOT --scheduler tcp://head:8786 --resume
    """
    from ..io.export import LAYOUTS, get_layout
    from ..pipelines.export import ExportOptions, run_export

    fixed = get_layout(layout, form=form).system
    if fixed is not None and system is not None and system.name != fixed:
        raise click.UsageError(
            f"--layout {layout} stores labels in the {fixed} system its trainer expects; "
            f"--system {system.name} cannot be used with it"
        )
    if form is not None and form not in LAYOUTS[layout].forms:
        raise click.UsageError(f"--form applies to --layout {' or '.join(LAYOUTS.filter(lambda c: c.forms))} only")
    if trainer is not None and trainer not in LAYOUTS[layout].trainers:
        raise click.UsageError(
            f"--trainer applies to --layout {' or '.join(LAYOUTS.filter(lambda c: c.trainers))} only (the layout "
            "Hopenet, 6DRepNet and 6DRepNet360 share)"
        )
    opts = ExportOptions(
        layout=layout,
        images=tuple(images),
        system=system,
        input_system=input_system,
        radians=radians,
        form=form,
        trainer=trainer,
        crop_scale=crop_scale,
        square=square,
        size=size,
        quality=quality,
        pad_value=pad_value,
        min_inside=min_inside,
        split=split,
        split_file=split_file,
        exclude=exclude,
        min_change=min_change,
        balance=balance,
        seed=seed,
        drop_images_with_rejects=drop_images_with_rejects,
        workers=workers,
        scheduler=scheduler,
        resume=resume,
        overwrite=overwrite,
        rejects=rejects,
        strict=strict,
        quiet=quiet,
    )
    s = run_export(
        list(labels), output, opts, progress=lambda total: progress(total, desc="export", quiet=quiet, unit="crops")
    )
    lines = [
        f"exported {s['exported']} of {s['labels']} labels ({s['layout']}, {s['system']}) -> {s['output']}",
        "per split: " + ", ".join(f"{k} {v}" for k, v in s["per_split"].items()),
    ]
    if s["rejected"]:
        lines.append(
            f"rejected {s['rejected']}: "
            + "; ".join(f"{v} {k}" for k, v in s["rejects_per_reason"].items())
            + (f" -> {rejects}" if rejects else "")
        )
    lines += s["notes"]
    echo_summary(lines, quiet)
