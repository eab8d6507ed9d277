"""``hpe draw`` as a job: read labels, draw each image once with all its rows, write them with the run.

The images (or contact sheets) are written into a staged folder
(:func:`hpe_cli.io.transaction.staged_dir`) and moved into the output folder
when the run commits: a failure leaves no image behind, and a rerun never
meets images of a failed run.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import HpeError
from ...io import Rejects, open_table
from ...io.label_source import label_source
from ...io.rejects import fail_all_rejected
from ...io.transaction import ensure_transaction, staged_dir
from ..pools import library_threads
from .errors import is_errors_table, run_draw_errors
from .options import DrawOptions
from .plan import RejectBook, check_output_exists, group_rows, plan_images
from .render import Faces, Output, draw_all
from .rows import face_placement, image_names, read_rows, row_namer


def run_draw(input_path, outdir, options: DrawOptions, *, progress=None) -> dict:
    """Draw every row of ``input_path`` into folder ``outdir``; return counts (``faces``, ``images``,
    ``sheets``, ``rejects``, ``system``).

    A table written by ``hpe evaluate -o`` (``gt_*`` and ``pred_*`` columns) is drawn by
    :func:`hpe_cli.pipelines.draw.errors.run_draw_errors` instead. ``progress``: a tqdm bar whose total is set.
    The pictures are drawn on ``options.threads`` threads, with OpenCV's and pyarrow's pools limited to as
    many (:func:`~hpe_cli.pipelines.pools.library_threads`).
    """
    with library_threads(options.threads):
        return _run_draw(Path(input_path), outdir, options, progress)


def _run_draw(input_path: Path, outdir, options: DrawOptions, progress) -> dict:
    """:func:`run_draw` once the libraries' pools are limited."""
    src = open_table(input_path, with_lines=True)
    if is_errors_table(src.columns):
        return run_draw_errors(input_path, outdir, options, progress=progress)
    if options.worst is not None or options.sort_by is not None:
        raise HpeError(
            f"{src.path}: --worst and --sort-by draw the output of `hpe evaluate -o` (columns "
            "gt_pitch..pred_roll), got a label table"
        )
    # the file's own system, else --system (which also names the captions' system)
    labels = label_source(src, options.system, option_is_output=True, mode=options.use)
    rows, read_rejects, rejects = _read(labels, options)
    frame = rows.frame
    where = row_namer(src, rows.lines)
    is_mat = input_path.is_dir() or input_path.suffix.lower() == ".mat"
    pose_para = is_mat or {"tdz", "scale"} <= set(src.columns)
    centre, L, from_td = face_placement(frame, pose_para, options.length)
    flip = options.tdy_origin == "bottom" or (options.tdy_origin == "auto" and pose_para)
    faces = Faces(rows.A, rows.angles, centre, L, from_td, flip)
    img_root = Path(options.images) if options.images else (input_path if input_path.is_dir() else input_path.parent)
    outdir = Path(outdir)
    items, bad_rows = _usable(rows, options, src.path)
    # check every input and output before drawing anything
    plan, missing = plan_images(
        items,
        img_root=img_root,
        outdir=outdir,
        canvas=options.canvas,
        frame=frame,
        where=where,
        overwrite=options.overwrite,
        check_exists=not options.grid,
    )
    book = RejectBook(rejects, frame, src, rows.lines, where)
    book.add(bad_rows + missing)
    sheet_paths = _sheet_paths(outdir, len(plan), options)
    if progress is not None:
        progress.total = len(plan)
        progress.refresh()
    with ensure_transaction(), staged_dir(outdir, options.overwrite) as stage:
        out = Output(Path(stage), outdir, options.grid, options.grid_cols, options.tile, sheet_paths)
        s = draw_all(plan, faces, out, options, book, progress)
        book.finish(s["images"])
        if read_rejects:  # unparseable rows, set aside before drawing, count in the summary too
            read = Counter(r.reason.split(":")[0] for r in read_rejects)
            s["rejects"] = dict(read + Counter(s["rejects"]))
        s["system"] = labels.resolved.describe()  # which system the labels were read in, and where that came from
        return s


def _read(labels, options: DrawOptions):
    """``(rows, rows the reader could not parse, Rejects)``; an empty table, or one whose every row is
    unparseable, is an error."""
    src = labels.table
    read_rejects: list = []  # rows the reader cannot parse: with --rejects they are rejects, not the run's end
    batches = None
    if options.rejects is not None:
        batches = []
        for b, rr in src.batches_with_rejects():
            batches.append(b)
            read_rejects += rr
    rows = read_rows(labels, options.radians, batches=batches)
    rejects = Rejects(options.rejects, options.overwrite, strict=options.strict, source=src.path)
    rejects.add_unreadable(read_rejects)
    if len(rows.frame) == 0 and read_rejects:
        rejects.check()  # --strict: nothing written
        fail_all_rejected(
            rejects,
            f"{src.path}: nothing drawn: all {len(read_rejects)} row(s) rejected "
            f"(first: line {read_rejects[0].line}: {read_rejects[0].reason})",
        )
    if len(rows.frame) == 0:
        raise HpeError(f"{src.path}: empty table (no rows)")
    return rows, read_rejects, rejects


def _usable(rows, options: DrawOptions, path):
    """``(items, bad_rows)``: the drawable rows grouped by image name (:func:`group_rows`), and
    ``[(row, reason)]`` of the rows without a usable label or image name."""
    frame, reasons = rows.frame, rows.reasons
    names = image_names(frame)
    if names is None and options.canvas is None:
        raise HpeError(
            f"{path}: expected an `image` (or `file`) column naming the images, or --image-size WxH "
            f"to draw on blank canvases; found {', '.join(frame.columns[:12])}"
        )
    bad_rows = [(int(i), reasons[i]) for i in np.flatnonzero(reasons != "")]
    if names is None:
        name_arr = np.array([f"row_{i:06d}.png" for i in range(len(frame))], dtype=object)
    else:
        name_arr = np.array(names, dtype=object)
        unnamed = np.flatnonzero((reasons == "") & pd.isna(name_arr))
        bad_rows += [(int(i), "no image name") for i in unnamed]
    usable = np.flatnonzero((reasons == "") & ~pd.isna(name_arr))
    return group_rows(name_arr, usable, options.limit), bad_rows


def _sheet_paths(outdir, n_pictures, options: DrawOptions) -> list:
    """The contact sheets' paths (checked absent unless ``overwrite``); empty without ``grid``."""
    if not options.grid:
        return []
    per_sheet = options.grid_cols * options.grid_cols
    n_sheets = max(1, -(-n_pictures // per_sheet))
    paths = [outdir / f"contact_sheet_{k + 1:03d}.png" for k in range(n_sheets)]
    for p in paths:
        check_output_exists(p, options.overwrite)
    return paths
