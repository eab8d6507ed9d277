"""COCO-style head-pose JSON, DirectMHP's schema (SPEC §7).

DirectMHP (``exps/AGORA/data_process_hpe.py``) trains from a COCO file whose
``images`` are ``{file_name, height, width, id}`` and whose ``annotations``
are ``{image_id, id, category_id: 1, bbox: [x, y, w, h], euler_angles: [pitch,
yaw, roll], face2d_pts: [[x...], [y...]], area, iscrowd: 0, segmentation: []}``
with a single ``person`` category. :func:`write_coco` writes that layout from
a label table, atomically.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import HpeError
from .layout import ANGLE_COLS, BBOX_COLS, landmark_count
from .writers import AtomicFile

CATEGORIES = [{"supercategory": "person", "id": 1, "name": "person"}]
#: written for a missing landmark (JSON has no NaN); AFLW2000-3D's own marker
MISSING_POINT = -1.0


def _finite_column(frame, col, path):
    v = frame[col].to_numpy(dtype=np.float64, na_value=np.nan)
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise HpeError(f"{path}: row {bad[0]}: expected a finite {col}, got {v[bad[0]]} "
                       f"({bad.size} such rows)")
    return v


def _image_sizes(frame, codes, n_images, width, height, path, cols=("image_width", "image_height")):
    """Per-image (width, height): from the table's columns, else the arguments."""
    sizes = []
    for col, given in ((cols[0], width), (cols[1], height)):
        if col in frame.columns:
            v = frame[col].to_numpy(dtype=np.float64, na_value=np.nan)
            if not np.isfinite(v).all() or (v <= 0).any():
                bad = int(np.flatnonzero(~(np.isfinite(v) & (v > 0)))[0])
                raise HpeError(f"{path}: row {bad}: expected a positive {col}, got {v[bad]}")
            per = np.full(n_images, np.nan)
            per[codes] = v
            lo = np.full(n_images, np.inf)
            hi = np.full(n_images, -np.inf)
            np.minimum.at(lo, codes, v)
            np.maximum.at(hi, codes, v)
            if (lo != hi).any():
                k = int(np.flatnonzero(lo != hi)[0])
                raise HpeError(f"{path}: image {k}: expected one {col} per image, got {lo[k]:g} and {hi[k]:g}")
            sizes.append(per.astype(np.int64))
        elif given is not None:
            sizes.append(np.full(n_images, int(given), dtype=np.int64))
        else:
            raise HpeError(f"{path}: expected an {col} column or an image size for the COCO 'images' entries")
    return sizes


def coco_dict(frame, *, width=None, height=None, info: dict | None = None, path="<coco>",
              image_size_cols=("image_width", "image_height")) -> dict:
    """Build the COCO dictionary of a label table (see :func:`write_coco`)."""
    missing = [c for c in ["image"] + BBOX_COLS + ANGLE_COLS if c not in frame.columns]
    if missing:
        raise HpeError(f"{path}: expected columns {', '.join(missing)} in the label table")
    files = frame["image"].astype(str).to_numpy()
    # images in order of first appearance; ids start at 1 (0 is falsy in some COCO tools)
    uniq, first, codes = np.unique(files, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    codes = rank[codes.reshape(-1)]
    names = uniq[order]
    w_img, h_img = _image_sizes(frame, codes, names.size, width, height, path, tuple(image_size_cols))
    box = np.stack([_finite_column(frame, c, path) for c in BBOX_COLS], axis=1)
    if (box[:, 2:] < 0).any():
        bad = int(np.flatnonzero((box[:, 2:] < 0).any(1))[0])
        raise HpeError(f"{path}: row {bad}: expected bbox_w, bbox_h >= 0, got {box[bad, 2]:g}, {box[bad, 3]:g}")
    ang = np.stack([_finite_column(frame, c, path) for c in ANGLE_COLS], axis=1)
    n_lm = landmark_count(frame.columns)
    if n_lm:
        xs = frame[[f"lm{i}_x" for i in range(n_lm)]].to_numpy(dtype=np.float64, na_value=np.nan)
        ys = frame[[f"lm{i}_y" for i in range(n_lm)]].to_numpy(dtype=np.float64, na_value=np.nan)
        gone = ~(np.isfinite(xs) & np.isfinite(ys))
        xs = np.where(gone, MISSING_POINT, xs).tolist()
        ys = np.where(gone, MISSING_POINT, ys).tolist()
        pts = [[x, y] for x, y in zip(xs, ys)]
    else:
        pts = [[] for _ in range(len(frame))]
    area = np.round(box[:, 2] * box[:, 3], 4).tolist()
    image_ids = (codes + 1).tolist()
    box_l, ang_l = box.tolist(), ang.tolist()
    images = [{"file_name": str(f), "height": int(h), "width": int(w), "id": i + 1}
              for i, (f, w, h) in enumerate(zip(names.tolist(), w_img.tolist(), h_img.tolist()))]
    annotations = [{"image_id": image_ids[k], "id": k + 1, "category_id": 1, "bbox": box_l[k],
                    "euler_angles": ang_l[k], "face2d_pts": pts[k], "area": area[k], "iscrowd": 0,
                    "segmentation": []} for k in range(len(frame))]
    return {"info": dict(info or {}), "licenses": [], "images": images, "annotations": annotations,
            "categories": CATEGORIES}


def write_coco(frame, path, overwrite: bool = False, *, width=None, height=None, info: dict | None = None,
               image_size_cols=("image_width", "image_height")):
    """Write a label table as DirectMHP-style COCO JSON, atomically.

    Parameters
    ----------
    frame : pandas.DataFrame
        One row per head: ``image`` (path, used as ``file_name``), ``bbox_x,
        bbox_y, bbox_w, bbox_h`` (pixels, top-left corner and size),
        ``pitch, yaw, roll`` (degrees, written as ``euler_angles`` in that
        order and in whatever system the table holds -- DirectMHP's own files
        use the ``whenet`` system), optionally ``lm{i}_x, lm{i}_y`` (pixels;
        written as ``face2d_pts = [[x0, x1, ...], [y0, y1, ...]]``, a missing
        point as -1) and ``image_width, image_height``.
    path : str or Path
        Output ``.json``; refused if it exists unless ``overwrite``.
    width, height : int, optional
        Image size for tables without the image-size columns.
    image_size_cols : (str, str)
        Names of the per-row image width and height columns, used when present.
    info : dict, optional
        Stored as the file's ``info`` object.

    Notes
    -----
    Image ids are 1, 2, ... in order of first appearance; annotation ids are
    1, 2, ... in row order; ``area`` is ``bbox_w * bbox_h``; ``category_id``
    is 1 (``person``). The output is strict JSON (no NaN).
    """
    atomic = AtomicFile(path, overwrite)  # refuse an existing file before doing any work
    doc = coco_dict(frame, width=width, height=height, info=info, path=path, image_size_cols=image_size_cols)
    with atomic as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, allow_nan=False)
    return Path(path)
