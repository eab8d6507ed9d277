"""``hpe augment``'s batches: the checks of the input's columns, then per batch the labels, sizes, landmarks,
boxes and ``tdx, tdy`` moved (:meth:`BatchPlan.work`, on a worker thread)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from ...errors import HpeError, UsageError
from ...geometry.augment import (
    augment_canonical,
    crop_affine,
    move_boxes,
    move_points,
    move_td,
    plane_matrix,
    plane_to_pixel,
)
from ...geometry.landmark_schemes import SCHEMES, flip_permutation, scheme_for_count
from ...io import BBOX_COLS, LABEL_COLS, MATRIX_COLS, batch_rotations, conversion_columns, landmark_cols, landmark_count
from ...io.images import row_ids
from ...io.label_source import LabelSource
from ...io.labels import batch_labels, numeric_column
from ...io.readers import LINE_COL
from ...rotation import canonical_to_labels, frobenius, soa
from .images import RowImages
from .options import AGREE_TOL, IMAGE_COLUMNS, AugmentOptions


def batches_or_empty(src):
    """The input's batches; one empty batch for an empty table, so the output still gets its columns."""
    any_batch = False
    for batch, read_rejects in src.batches_with_rejects():
        any_batch = True
        yield batch, read_rejects
    if not any_batch:
        yield pa.RecordBatch.from_pydict({f.name: pa.array([], type=f.type) for f in src.schema}, schema=src.schema), []


def _is_numeric_type(t) -> bool:
    return (
        pa.types.is_integer(t)
        or pa.types.is_floating(t)
        or pa.types.is_decimal(t)
        or pa.types.is_null(t)
        or pa.types.is_boolean(t)
    )


def plan_landmarks(path, columns, scheme, op):
    """(number of landmarks to move, permutation or None, summary text).

    Raises
    ------
    HpeError
        A mirror of landmarks no built-in scheme re-indexes, or ``--landmarks SCHEME`` against another count.
    """
    n = landmark_count(columns)
    mirror = op in ("hflip", "vflip", "mirror")
    if scheme == "none":
        return 0, None, f"none ({n} landmark columns pairs left unchanged)" if n else "none"
    if scheme == "auto":
        if n == 0:
            return 0, None, "none in input"
        name = scheme_for_count(n)
        if name is None and mirror:
            raise HpeError(
                f"{path}: {n} landmarks (lm0_x..lm{n - 1}_y) match no built-in scheme "
                f"(ibug68, face70, aflw21), and a mirror must re-index them; "
                "use --landmarks none to leave them unchanged"
            )
        return (
            n,
            (None if name is None else flip_permutation(name)),
            f"{n} moved" + (f", scheme {name}" if name else ""),
        )
    want = SCHEMES[scheme].size
    if n != want:
        raise HpeError(
            f"{path}: --landmarks {scheme} expects {want} landmark column pairs lm0_x..lm{want - 1}_y, got {n}"
        )
    return n, flip_permutation(scheme), f"{n} moved, scheme {scheme}"


def size_source(columns, image_size, images_dir, path) -> bool:
    """Whether the table's ``image_width/image_height`` columns give image sizes; a usage error when neither
    they, ``image_size`` nor ``images_dir`` does."""
    has_cols = "image_width" in columns and "image_height" in columns
    if not has_cols and image_size is None and images_dir is None:
        raise UsageError(
            f"{path}: expected the image size: --image-size WxH, image_width/image_height columns "
            "or --images (the images themselves); got none"
        )
    return has_cols


def row_sizes(batch, image_size, has_cols, pics, names, ids):
    """Per-row input size (N, 2), the picture refs, and a reason per row ('' when the sizes agree).

    Sources: the images (``pics``), the ``image_width/image_height`` columns, ``--image-size``; each row uses
    the first that gives a size, and any two that disagree reject the row.
    """
    n = batch.num_rows
    reasons = np.full(n, "", dtype=object)
    col = np.full((n, 2), np.nan)
    if has_cols:
        col = np.stack([numeric_column(batch, "image_width")[0], numeric_column(batch, "image_height")[0]], -1)
    img = np.full((n, 2), np.nan)
    refs = [None] * n
    if pics is not None:
        seqs, cams, frs = ids
        for i in range(n):
            if names[i] is None:
                reasons[i] = "no image name"
                continue
            ref, size, why = pics.lookup(names[i], seqs[i], cams[i], frs[i])
            refs[i] = ref
            if why:
                reasons[i] = why
            elif size is not None:
                img[i] = size
    opt = np.full((n, 2), np.nan) if image_size is None else np.broadcast_to(np.asarray(image_size, float), (n, 2))
    labelled = (("the image", img), ("image_width/image_height", col), ("--image-size", opt))
    wh = np.full((n, 2), np.nan)
    for _, v in reversed(labelled):
        wh = np.where(np.isfinite(v).all(1, keepdims=True), v, wh)
    for k, (na, va) in enumerate(labelled):
        for nb, vb in labelled[k + 1 :]:
            both = np.isfinite(va).all(1) & np.isfinite(vb).all(1) & (reasons == "")
            bad = both & (va != vb).any(1)
            for i in np.flatnonzero(bad):
                reasons[i] = f"image size: {na} is {va[i, 0]:g}x{va[i, 1]:g}, {nb} says {vb[i, 0]:g}x{vb[i, 1]:g}"
    none = ~np.isfinite(wh).all(1) & (reasons == "")
    reasons[none] = "no image size (image_width/image_height empty; give --image-size or --images)"
    bad = (reasons == "") & ((wh < 1) | (wh != np.round(wh))).any(1)
    reasons[bad] = "image size: expected whole numbers of pixels >= 1"
    return wh, refs, reasons


def image_column(path, columns, images_dir, out_images, image_column):
    """The column naming each row's image (None without --images); usage errors for the image options."""
    if out_images is not None and images_dir is not None and Path(out_images).resolve() == Path(images_dir).resolve():
        raise HpeError(f"{out_images}: --out-images must differ from --images (inputs are never modified)")
    if images_dir is None:
        if image_column is not None:
            raise HpeError("--image-column needs --images")
        return None
    img_col = image_column or next((c for c in IMAGE_COLUMNS if c in columns), None)
    if img_col is None or img_col not in columns:
        raise HpeError(
            f"{path}: expected an image column ({image_column or ', '.join(IMAGE_COLUMNS)}) "
            "to go with --images, got none"
        )
    return img_col


def pixel_transform(op, M, wh, crop, scale=None):
    """Per-row pixel affine (N, 2, 3), output size (N, 2) and reasons ('' or why the row cannot be resized)."""
    n = len(wh)
    reasons = np.full(n, "", dtype=object)
    safe = np.where(np.isfinite(wh), wh, 1.0)
    if op == "crop":
        x, y, cw, ch = crop
        return (
            np.broadcast_to(crop_affine(x, y), (n, 2, 3)),
            np.broadcast_to(np.array([cw, ch], float), wh.shape),
            reasons,
        )
    if op == "scale":
        out = np.round(safe * scale)
        whole = (np.abs(safe * scale - out) < 1e-6).all(1) & (out >= 1).all(1)
        for i in np.flatnonzero(~whole):
            reasons[i] = (
                f"scale: {safe[i, 0]:g}x{safe[i, 1]:g} times {scale:g} is not a whole number of pixels "
                "(the aspect would change)"
            )
        out = np.where(whole[:, None], out, safe)
        P = np.zeros((n, 2, 3))
        P[:, 0, 0] = P[:, 1, 1] = scale
        P[:, :, 2] = 0.5 * scale - 0.5
        return P, out, reasons
    return plane_to_pixel(np.asarray(M), safe), safe, reasons


class BatchPlan:
    """What every batch needs: the label reader, the landmark/box/size columns, the transform.

    Built once per run from the opened labels and the options; the checks of the input's columns against the
    options (landmark scheme, box columns, the image size's source, the image column) run here, in that order.
    """

    def __init__(self, labels: LabelSource, opts: AugmentOptions):
        path, columns = Path(labels.path), labels.columns
        self.path, self.src, self.in_system, self.system = path, labels.table, labels.system, labels.output_system
        self.n_lm, self.perm, self.lm_text = plan_landmarks(path, columns, opts.scheme, opts.op)
        box_present = [c for c in BBOX_COLS if c in columns]
        if box_present and len(box_present) != 4:
            raise HpeError(f"{path}: expected all of {', '.join(BBOX_COLS)}, got only {', '.join(box_present)}")
        self.has_box = bool(box_present)
        self.has_cols = size_source(columns, opts.image_size, opts.images_dir, path)
        self.img_col = image_column(path, columns, opts.images_dir, opts.out_images, opts.image_column)
        self.M = plane_matrix(opts.op, opts.angle) if opts.op not in ("crop", "scale") else np.eye(2)
        is_mat = path.is_dir() or path.suffix.lower() == ".mat"
        self.pose_para = is_mat or {"tdz", "scale"} <= set(columns)
        self.pics = RowImages(opts.images_dir, opts.images_optional) if opts.images_dir else None
        self._read_labels(labels, columns)
        self.lm_names = landmark_cols(self.n_lm)
        self.op, self.crop, self.image_size, self.scale = opts.op, opts.crop, opts.image_size, opts.scale
        self.box_from, self.clip, self.radians = opts.box_from, opts.clip, opts.radians
        self.has_td = "tdx" in columns and "tdy" in columns
        self.zoom = opts.scale if opts.op == "scale" else 1.0  # lengths in pixels (size, Pose_Para scale) change
        self.zoom_cols = (
            [c for c in ("size", "scale") if c in columns and (c == "size" or self.pose_para)]
            if opts.op == "scale"
            else []
        )
        self.mirror = bool(np.linalg.det(self.M) < 0)
        self.csv = labels.table.kind == "csv"
        self.mat_base = (path if path.is_dir() else path.parent) if is_mat and "file" in columns else None
        #: a ``.mat`` folder whose images are written: its ``.mat`` files are written back beside them
        self.mat_input = labels.dataset and is_mat and opts.out_images is not None

    def _read_labels(self, labels: LabelSource, columns):
        """How the labels are read: the system's own stored kind, angles (checked against ``r00..r22`` when the
        table has both), or ``r00..r22``."""
        in_system = labels.system
        self.mode = labels.mode  # the system's own columns, else angles, else r00..r22
        self.stored_kind = self.mode not in ("angles", "matrix") or bool(
            in_system.columns and all(c in columns for c in in_system.value_columns)
        )
        self.cross_check = self.mode == "angles" and not self.stored_kind and all(c in columns for c in MATRIX_COLS)
        self.label_source = (
            "pitch,yaw,roll" + (" (checked against r00..r22)" if self.cross_check else "")
            if self.mode == "angles"
            else "r00..r22"
        )

    def numbers(self, lines):
        """The row numbers messages and rejects use: CSV lines (header = 1), else 1-based rows (the reader's
        ``__line__`` already is that number)."""
        return lines

    def where(self, line, file=None) -> str:
        """How messages name a row: ``FILE: line N`` (text), the ``.mat`` file itself (a ``.mat`` folder: one
        record per file), else ``FILE: row N`` (1-based)."""
        if self.mat_base is not None and file is not None:
            return str(self.mat_base / str(file))
        return self.src.where(line)

    def roi_fn(self, roi, size_in):
        """``roi`` (x1, y1, x2, y2) of the original photo shown by the image: a crop shows the sub-rectangle;
        a flip or a turn about the centre shows the same region (so it is kept)."""
        if self.op != "crop":
            return roi
        x, y, cw, ch = self.crop
        r = roi.reshape(-1)
        sx, sy = (r[2] - r[0]) / size_in[0], (r[3] - r[1]) / size_in[1]
        return np.array([r[0] + x * sx, r[1] + y * sy, r[0] + (x + cw) * sx, r[1] + (y + ch) * sy])

    def labels(self, batch):
        """(matrices of the input system, reasons) of a batch."""
        n = batch.num_rows
        if self.stored_kind:  # rotation vectors, quaternions, 6-D, named columns: read as matrices
            X, _, reasons = batch_rotations(batch, self.in_system, self.mode, self.radians)
            return soa.to_array(X, n), (reasons if reasons is not None else np.full(n, "", dtype=object))
        values, reasons = batch_labels(batch, self.mode, self.radians)  # --radians: input angles in radians
        if self.mode != "angles":
            return values, reasons
        R = self.in_system.from_angles(np.where(np.isfinite(values), values, 0.0))
        if self.cross_check:  # a table with both must agree, or which one is the label?
            R_in, r_in = batch_labels(batch, "matrix")
            reasons = np.where(reasons == "", r_in, reasons)
            ok = reasons == ""
            gap = np.zeros(n)
            gap[ok] = frobenius(R[ok], R_in[ok])
            reasons[ok & (gap > AGREE_TOL)] = "angles and r00..r22 disagree"
        return R, reasons

    def work(self, batch):
        """On a worker thread: labels, sizes, landmarks, boxes, tdx/tdy of one batch."""
        lines = batch.column(LINE_COL).to_numpy()
        batch = batch.drop_columns([LINE_COL])
        n = batch.num_rows
        R, reasons = self.labels(batch)
        wh, refs, names, size_reasons = self._sizes(batch)
        reasons = np.where(reasons == "", size_reasons, reasons)
        extra, reasons = self._positions(batch, reasons)
        P, wh_out, scale_reasons = pixel_transform(self.op, self.M, wh, self.crop, self.scale)
        reasons = np.where(reasons == "", scale_reasons, reasons)
        keep = reasons == ""
        kb = batch.filter(pa.array(keep)) if not keep.all() else batch
        A2 = augment_canonical(self.in_system.to_canonical(R[keep]), self.M)
        new = conversion_columns(canonical_to_labels(A2, self.system))
        boxes = self._move_positions(new, extra, keep, P[keep], wh[keep], wh_out[keep])
        out = _output_batch(kb, new)
        A2_full = np.full((n, 3, 3), np.nan)
        A2_full[keep] = A2
        files = batch.column("file").to_pylist() if "file" in batch.schema.names else None
        return batch, lines, reasons, keep, out, boxes, (refs, names, P, wh, wh_out, A2_full, files)

    def _sizes(self, batch):
        """``(sizes (N, 2), picture refs, image names, reasons)`` of a batch's rows (:func:`row_sizes`)."""
        names = ids = None
        if self.pics is not None:
            names = [None if v is None else str(v) for v in batch.column(self.img_col).to_pylist()]
            ids = row_ids(
                batch.select([c for c in ("sequence", "camera", "frame") if c in batch.schema.names]).to_pandas()
            )
        wh, refs, reasons = row_sizes(batch, self.image_size, self.has_cols, self.pics, names, ids)
        return wh, refs, names, reasons

    def _positions(self, batch, reasons):
        """The landmark, box, ``tdx, tdy`` and length columns as numbers, and the reasons with a row whose text
        holds a non-number among them (NaN means missing and is kept)."""
        extra = {}
        for c in (
            self.lm_names
            + (BBOX_COLS if self.has_box else [])
            + (["tdx", "tdy"] if self.has_td else [])
            + self.zoom_cols
        ):
            v, r = numeric_column(batch, c)
            extra[c] = v
            if not _is_numeric_type(batch.schema.field(c).type):  # only text can hold non-numbers
                bad = np.char.startswith(r.astype(str), "non-numeric")
                reasons = np.where((reasons == "") & bad, r, reasons)
        return extra, reasons

    def _move_positions(self, new, extra, keep, P, wh, wh_out) -> int:
        """Add the moved landmarks, boxes, ``tdx, tdy``, lengths and image sizes of the kept rows to ``new``;
        return the number of boxes moved. ``extra``: the batch's columns (all rows; ``keep`` picks them one at a
        time, so no second copy of every column is held); ``P``, ``wh``, ``wh_out``: of the kept rows."""
        lm_new = None
        if self.n_lm:
            lm = np.stack([extra[c][keep] for c in self.lm_names], axis=-1).reshape(-1, self.n_lm, 2)
            lm_new = move_points(lm, P, self.mirror, self.perm)
            flat = lm_new.reshape(-1, 2 * self.n_lm)
            new.update({c: flat[:, i] for i, c in enumerate(self.lm_names)})
        boxes = 0
        if self.has_box:
            box = np.stack([extra[c][keep] for c in BBOX_COLS], axis=-1)
            box_new = move_boxes(box, P, self.M, wh_out, lm_new, self.box_from, self.clip)
            boxes = int(np.isfinite(box_new).all(axis=1).sum())
            new.update({c: box_new[:, i] for i, c in enumerate(BBOX_COLS)})
        if self.has_td:
            new["tdx"], new["tdy"] = move_td(
                extra["tdx"][keep], extra["tdy"][keep], P, wh[:, 1], wh_out[:, 1], self.pose_para
            )
        for c in self.zoom_cols:
            new[c] = extra[c][keep] * self.zoom
        if self.has_cols:
            new["image_width"], new["image_height"] = wh_out[:, 0].astype(np.int64), wh_out[:, 1].astype(np.int64)
        return boxes


def _output_batch(kb, new) -> pa.RecordBatch:
    """The kept rows with their new columns: the input's columns in place, new label columns appended."""
    out_cols, out_names = [], []
    for i, c in enumerate(kb.schema.names):
        out_names.append(c)
        out_cols.append(pa.array(new.pop(c)) if c in new else kb.column(i))
    for c in LABEL_COLS:
        if c in new:
            out_names.append(c)
            out_cols.append(pa.array(new.pop(c)))
    return pa.RecordBatch.from_arrays(out_cols, names=out_names)
