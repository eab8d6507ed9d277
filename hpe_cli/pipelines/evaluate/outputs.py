"""``hpe evaluate`` outputs kept in flat memory: the per-row table of a chunk, the worst rows, a plot sample,
the image files by stem, and the pictures of the worst rows (drawn by ``hpe draw``)."""

from __future__ import annotations

import base64
import os
from types import SimpleNamespace

import numpy as np
import pyarrow as pa

from .sides import Chunk, file_stems

ANGLES = ("pitch", "yaw", "roll")


class Worst:
    """The ``n`` pairs with the largest geodesic error, kept across chunks."""

    def __init__(self, n: int):
        self.n = n
        self.frame = None

    def add(self, table):

        if not self.n or not table.num_rows:
            return
        import pyarrow.compute as pc  # lazy: start-up (0.06 s; only --report keeps the worst pairs)

        if table.num_rows > self.n:
            geo = table.column("geodesic").to_numpy()
            table = table.take(pa.array(np.argpartition(-geo, self.n - 1)[: self.n]))
        t = table if self.frame is None else pa.concat_tables([self.frame, table], promote_options="permissive")
        order = pc.sort_indices(t, sort_keys=[("geodesic", "descending")])
        self.frame = t.take(order).slice(0, self.n)


class Sample:
    """Rows kept for the plots: all of them up to ``cap``, then every k-th (k doubling), float32."""

    def __init__(self, cap: int = 400_000):
        self.cap, self.step, self.seen = cap, 1, 0
        self.parts: list = []

    @staticmethod
    def block(rows) -> np.ndarray:
        """The plotted columns of every row of a chunk, float32 (any thread may compute it)."""
        out = np.empty((rows.n, 5), dtype=np.float32)
        out[:, 0], out[:, 1], out[:, 2:5] = rows.gt_angles[:, 1], rows.geodesic, rows.mae_wrapped
        return out

    def add(self, rows, block=None):
        n = rows.n
        idx = np.arange((-self.seen) % self.step, n, self.step)
        self.seen += n
        part = (self.block(rows) if block is None else block)[idx]
        self.parts.append(part)
        if sum(len(p) for p in self.parts) > self.cap:
            allp = np.concatenate(self.parts)
            self.parts = [allp[::2]]
            self.step *= 2

    def rows(self):

        a = np.concatenate(self.parts) if self.parts else np.zeros((0, 5), dtype=np.float32)
        a = a.astype(np.float64)
        gt = np.zeros((len(a), 3))
        gt[:, 1] = a[:, 0]
        return SimpleNamespace(n=len(a), gt_angles=gt, geodesic=a[:, 1], mae_wrapped=a[:, 2:5], step=self.step)


def row_table(rows, g: Chunk, p: Chunk, keys, by, by_values, images):
    """The per-row output of one chunk: keys, angles in the GT system, errors, extras."""

    cols = {}
    if keys:
        for k in keys:
            cols[k] = g.keys.column(k)
    else:
        cols["gt_line"] = pa.array(g.lines)
        cols["pred_line"] = pa.array(p.lines)
    if by and by not in cols:
        cols[by] = pa.array(by_values)
    for k, a in enumerate(ANGLES):
        cols[f"gt_{a}"] = pa.array(rows.gt_angles[:, k])
    for k, a in enumerate(ANGLES):
        cols[f"pred_{a}"] = pa.array(rows.pred_angles[:, k])
    for k, a in enumerate(ANGLES):
        cols[f"err_{a}"] = pa.array(rows.mae_wrapped[:, k])
    cols["geodesic"] = pa.array(rows.geodesic)
    for k, a in enumerate(("left", "down", "front")):
        cols[f"maev_{a}"] = pa.array(rows.maev[:, k])
    cols["frobenius"] = pa.array(rows.frobenius)
    if p.dist is not None:
        cols["pred_rotation_distance"] = pa.array(p.dist)
    if images is not None and g.keys is not None and "image" in g.keys.column_names:
        cols["image_path"] = images.paths(g.keys.column("image"))
    return pa.table({k: (v.combine_chunks() if isinstance(v, pa.ChunkedArray) else v) for k, v in cols.items()})


class Images:
    """Image files of one folder by stem (listed once), for the per-row output and the report's pictures."""

    def __init__(self, folder):

        self.folder = folder
        exts = (".jpg", ".jpeg", ".png", ".bmp")
        self.by_stem = {}
        for name in sorted(os.listdir(folder)):
            stem, ext = os.path.splitext(name)
            if ext.lower() in exts:
                self.by_stem.setdefault(stem, os.path.join(folder, name))

    def paths(self, names):
        """The image path of each name (matched on the file stem), '' when the folder has none."""
        import pyarrow.compute as pc  # lazy: start-up (0.06 s; the streamed run with equal keys needs none)

        if isinstance(names, pa.ChunkedArray):
            names = names.combine_chunks()
        stems = file_stems(pc.cast(names, pa.string()))
        idx = pc.index_in(stems, value_set=pa.array(list(self.by_stem), pa.string()))
        out = (
            pa.array(list(self.by_stem.values()), pa.string()).take(pc.fill_null(idx, 0))
            if self.by_stem
            else pa.nulls(len(stems), pa.string())
        )
        return pc.if_else(pc.is_null(idx), "", out)


def worst_pictures(frame, images, system, fallback_root=None, max_side: int = 480):
    """GT and prediction drawn on the face for each worst row, as JPEG data URIs (None where no image is found).

    Drawn by ``hpe draw``'s :func:`~hpe_cli.pipelines.draw.render_worst` (the pictures ``draw_worst``
    writes, kept in memory: nothing is staged or written); images found by :mod:`hpe_cli.io.images` under
    ``images`` (``--images`` or the GT folder), else ``fallback_root``, ``.mat`` + ``.jpg`` folders and
    Panoptic layouts included. ``system`` is the GT system (the angles of ``frame``).
    """
    import cv2

    from ..draw import render_worst  # lazy: pandas and OpenCV, only for the page's worst-row pictures

    if frame is None or not len(frame):
        return None
    root = images.folder if images is not None else fallback_root
    if root is None:
        return None
    out: list = [None] * len(frame)
    for _, i, img, _, _, _ in render_worst(
        frame,
        images=root,
        sort_by="geodesic",
        system=system,
        on_missing="skip",
        where="worst rows",
        crop=lambda im, i: _around_face(im, frame.iloc[i]),
    ):
        scale = max_side / max(img.shape[:2])
        if scale < 1:
            img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 85])
        if ok:
            out[i] = "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode("ascii")
    return out


def _around_face(img, row):
    """``(part, (x0, y0))``: the part of a large frame around the row's face box (3 box heights wide, as the
    audit page crops) and its top-left corner; the whole image when the row has no box or the image is small."""
    try:
        x, y, w, h = (float(row[c]) for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h"))
    except (KeyError, TypeError, ValueError):
        return img, (0, 0)
    H, W = img.shape[:2]
    if not np.isfinite([x, y, w, h]).all() or max(H, W) <= 640:
        return img, (0, 0)
    half = max(3 * h / 2, 80.0)
    cx, cy = x + w / 2, y + h / 2
    x0, x1 = int(max(0, cx - half)), int(min(W, cx + half))
    y0, y1 = int(max(0, cy - half)), int(min(H, cy + half))
    return (img[y0:y1, x0:x1], (x0, y0)) if x1 - x0 > 8 and y1 - y0 > 8 else (img, (0, 0))


def empty_rows(keys):

    cols = {k: pa.array([], pa.string()) for k in keys}
    for pre in ("gt_", "pred_", "err_"):
        cols.update({pre + a: pa.array([], pa.float64()) for a in ANGLES})
    cols["geodesic"] = pa.array([], pa.float64())
    return pa.table(cols)
