"""Export stage 3, place pixels (parent side): the crop box and written size of every head, one task per source
image (or Panoptic video), and the loop that runs the tasks (in worker processes with ``--workers``) and hands
the finished heads and their pixels to the layout."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...geometry.crop import expand_boxes, pixel_boxes
from ...io.images import leaves_root, resolve_image, video_path
from ...io.layout import BBOX_COLS
from ..pools import in_order
from . import units as U
from .units import link_files
from .workers import unspill
from .write import add_pixels


@dataclass
class CropPlan:
    """Crop geometry of every row: head box, crop box in pixels (exclusive ends), written size, file name."""

    scale: float
    square: bool
    size: int | None
    bbox: np.ndarray
    pbox: np.ndarray
    osz: np.ndarray
    rel: np.ndarray | None = None


def plan_crops(sel, layout, opts) -> CropPlan:
    """Crop boxes from the head boxes (``--crop-scale``, ``--square``, the layout's own boxes) and sizes."""
    rows, reasons, n = sel.rows, sel.reasons, sel.n
    scale = opts.crop_scale if opts.crop_scale is not None else 1.0
    square = layout.default_square if opts.square is None else opts.square
    size = opts.size if opts.size is not None else layout.default_size
    bbox = rows[BBOX_COLS].to_numpy(np.float64)
    cbox = layout.crop_boxes(rows, expand_boxes(np.nan_to_num(bbox, nan=0.0), scale, square), sel.lm)
    ok = reasons == ""
    reasons[ok & ~np.isfinite(cbox).all(1)] = "no crop box"
    cbox = np.nan_to_num(cbox, nan=0.0)
    pbox = pixel_boxes(cbox)
    cw, ch = pbox[:, 2] - pbox[:, 0], pbox[:, 3] - pbox[:, 1]
    if size is not None:
        if square or layout.stretch:
            osz = np.stack([np.full(n, size), np.full(n, size)], 1)
        else:
            osz = np.stack([np.full(n, size), np.maximum(1, np.round(size * ch / np.maximum(cw, 1)))], 1)
    else:
        osz = np.stack([cw, ch], 1)
    return CropPlan(scale, bool(square), size, bbox, pbox, osz.astype(np.int64))


def name_files(sel, layout, plan: CropPlan, todo) -> None:
    """The layout's file name of each row to export, split by split."""
    rel = np.empty(sel.n, dtype=object)
    for s in np.unique(sel.split[todo]).tolist():
        idx = todo[sel.split[todo] == s]
        rel[idx] = layout.relpath(sel.rows.iloc[idx], s)
    plan.rel = rel


def build_tasks(sel, layout, plan: CropPlan, todo) -> list:
    """One task per source image (or per Panoptic video): ``[kind, source path, items]``."""
    rows, split = sel.rows, sel.split
    roots = rows["root"].to_numpy(dtype=object)
    images = rows["image"].to_numpy(dtype=object)
    seqs = rows["sequence"].to_numpy(dtype=object)
    cams = rows["camera"].to_numpy(dtype=object)
    frames = rows["frame"].to_numpy()
    full_frames = layout.full_frames
    want = np.stack([rows["image_width"].to_numpy(np.float64), rows["image_height"].to_numpy(np.float64)], 1)
    task_of = {}
    tasks = []
    for i in todo.tolist():
        key = (roots[i], seqs[i], images[i])  # one name (hdImgs/00_00/00_00_00000001.jpg) in two sequences
        t = task_of.get(key)
        if t is None and leaves_root(images[i]):
            t = task_of[key] = ["refused", f"image name {images[i]!r} leaves the --images folder (refused)", []]
            tasks.append(t)
        elif t is None:
            src = resolve_image(roots[i], images[i], seqs[i], cams[i], int(frames[i]))
            if src is None and cams[i] and frames[i] >= 0:
                vkey = ("video", roots[i], seqs[i], cams[i])
                t = task_of.get(vkey)
                if t is None:
                    t = task_of[vkey] = ["video", video_path(roots[i], seqs[i], cams[i]), {}]
                    tasks.append(t)
                task_of[key] = t
            else:
                t = task_of[key] = ["image", src, []]
                tasks.append(t)
        size = tuple(int(v) for v in want[i]) if np.isfinite(want[i]).all() and (want[i] > 0).all() else None
        item = (
            i,
            split[i],
            plan.rel[i],
            tuple(plan.pbox[i].tolist()),
            tuple(plan.bbox[i].tolist()),
            None if full_frames else tuple(plan.osz[i].tolist()),
            size,
        )
        if t[0] == "video":
            t[2].setdefault(int(frames[i]), []).append(item)
        else:
            t[2].append(item)
    return tasks


def unit_results(units, cfg, pool, parts=None, resume: bool = False):
    """Yield each unit's ``(results, spill file or None, files folder or None)``, in unit order, computed on
    ``pool`` (:func:`hpe_cli.pipelines.pools.unit_pool`). Without ``parts`` the units write into the staging
    folder and hand back their results; with a parts folder they write parts (:mod:`.units`), and with
    ``resume`` the units already done there are not computed again."""

    if parts is None:
        tasks = [U.unit_task(cfg, u, None) for u in units]
        for res, spill in in_order(pool, U.run_unit, tasks):
            yield res, spill, None
        return
    stems = [os.path.join(os.path.abspath(parts), f"{k:06d}") for k in range(len(units))]  # workers: elsewhere
    if resume:
        U.check_done(stems)
    todo = [U.unit_task(cfg, u, s) for u, s in zip(units, stems) if not os.path.exists(s + ".json")]
    need = {t["stem"] for t in todo}
    computed = in_order(pool, U.run_unit, todo)
    for stem in stems:
        if stem in need:
            next(computed)  # in order: this unit's parts are complete after it
        yield U.read_unit(stem)


#: heads handed to the layout at a time (pixel layouts: one Parquet row group, one slice of the .npz)
FLUSH = 256


@dataclass
class PixelResult:
    """What the tasks gave back: per row, its image-level reject (``''``), written order and image size."""

    status: np.ndarray
    order: np.ndarray
    W: np.ndarray
    H: np.ndarray


def run_tasks(results, sel, layout, plan: CropPlan, stage, bar=None, keep_parts: bool = False) -> PixelResult:
    """Take every unit's results (:func:`unit_results`), in order: link the files units wrote in their parts
    into the staging folder ``stage`` and pass finished heads (with their pixels) to the layout in small
    slices. ``keep_parts``: leave the spill files (parts of a resumable run)."""

    n = sel.n
    res_all = PixelResult(
        np.full(n, "", dtype=object),
        np.full(n, -1, dtype=np.int64),
        sel.rows["image_width"].to_numpy(np.float64).copy(),
        sel.rows["image_height"].to_numpy(np.float64).copy(),
    )
    status, order, W, H = res_all.status, res_all.order, res_all.W, res_all.H
    counter = 0
    made: set = set()
    good, payloads = [], []  # heads waiting for the layout, across units
    try:
        for res, spill, files in results:
            if files is not None and os.path.isdir(files):
                link_files(files, Path(stage), made)
            spill_fh = open(spill, "rb") if spill else None
            try:
                for idx, reason, w, h, payload in res:
                    if w > 0:
                        W[idx], H[idx] = w, h
                    if reason:
                        status[idx] = reason
                        continue
                    order[idx] = counter
                    counter += 1
                    if layout.pixels == "file":
                        continue
                    good.append(idx)
                    payloads.append(unspill(payload, spill_fh))
                    # slices of FLUSH heads, whatever the units: the layout's row groups and shards are the
                    # same for every runner
                    if len(good) >= FLUSH:
                        add_pixels(layout, sel, plan, res_all, good, payloads, None)
                        good, payloads = [], []
            finally:
                if spill_fh is not None:
                    spill_fh.close()
            if spill is not None and not keep_parts:
                os.unlink(spill)
            if bar is not None:
                bar.update(len(res))
        if good:
            add_pixels(layout, sel, plan, res_all, good, payloads, None)
    finally:
        results.close()
    return res_all


def worker_config(stage, layout, splits_used, opts) -> dict:
    """The settings every worker reads (``workers._CFG``)."""
    split_dirs = {s: str(layout.split_dir(s).relative_to(stage)) for s in splits_used}
    return {
        "root": os.path.abspath(stage),  # workers may run in another folder (Dask)
        "split_dirs": split_dirs,
        "quality": int(opts.quality),
        "pad_value": int(opts.pad_value),
        "min_inside": float(opts.min_inside),
        "full_frames": layout.full_frames,
        "pixels": layout.pixels,
        "made": set(),
    }
