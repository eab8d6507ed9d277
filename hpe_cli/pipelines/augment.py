"""``hpe augment`` as a streaming job: read batches, move labels/landmarks/boxes (and images), write."""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ..errors import HpeError

#: columns tried, in order, for the image file name when --image-column is not given
IMAGE_COLUMNS = ("image", "image_path", "img_path", "file_name", "filename", "file", "path")
_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
#: rows whose angles and r00..r22 disagree by more than this (Frobenius) are rejected
AGREE_TOL = 1e-3


def _batches_or_empty(src):
    """The input's batches; one empty batch for an empty table, so the output still gets its columns."""
    import pyarrow as pa

    any_batch = False
    for batch, read_rejects in src.batches_with_rejects():
        any_batch = True
        yield batch, read_rejects
    if not any_batch:
        yield pa.RecordBatch.from_pydict({f.name: pa.array([], type=f.type) for f in src.schema}, schema=src.schema), []


def _is_numeric_type(t) -> bool:
    import pyarrow as pa

    return (
        pa.types.is_integer(t)
        or pa.types.is_floating(t)
        or pa.types.is_decimal(t)
        or pa.types.is_null(t)
        or pa.types.is_boolean(t)
    )


def _plan_landmarks(path, columns, scheme, op):
    """(number of landmarks to move, permutation or None, summary text)."""
    from ..errors import HpeError
    from ..geometry.landmark_schemes import SCHEMES, flip_permutation, scheme_for_count
    from ..io import landmark_count

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


def _size_source(columns, image_size, images_dir, path):
    """Which sources give image sizes; a usage error when none does."""
    has_cols = "image_width" in columns and "image_height" in columns
    if not has_cols and image_size is None and images_dir is None:
        from ..errors import UsageError

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
    import numpy as np

    from ..io.labels import numeric_column

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


def _image_column(path, columns, images_dir, out_images, image_column):
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


def _pixel_transform(op, M, wh, crop, scale=None):
    """Per-row pixel affine (N, 2, 3), output size (N, 2) and reasons ('' or why the row cannot be resized)."""
    from ..geometry.augment import _affine, crop_affine

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
    return _affine(np.asarray(M), safe), safe, reasons


class _Plan:
    """What every batch needs: the label reader, the landmark/box/size columns, the transform."""

    def __init__(
        self,
        path,
        src,
        in_system,
        system,
        columns,
        n_lm,
        perm,
        has_box,
        M,
        op,
        crop,
        image_size,
        has_cols,
        box_from,
        clip,
        pose_para,
        img_col,
        pics,
        scale=None,
        radians=False,
    ):
        from ..io import MATRIX_COLS, landmark_cols
        from ..io.labels import label_mode

        self.path, self.src, self.in_system, self.system = path, src, in_system, system
        self.mode = label_mode(columns, path, in_system)  # the system's own columns, else angles, else r00..r22
        self.stored_kind = self.mode not in ("angles", "matrix") or bool(
            in_system.columns and all(c in columns for c in in_system.value_columns)
        )
        self.cross_check = self.mode == "angles" and not self.stored_kind and all(c in columns for c in MATRIX_COLS)
        self.n_lm, self.perm, self.lm_names, self.has_box = n_lm, perm, landmark_cols(n_lm), has_box
        self.M, self.op, self.crop, self.image_size, self.has_cols = M, op, crop, image_size, has_cols
        self.box_from, self.clip, self.pose_para, self.img_col, self.pics = box_from, clip, pose_para, img_col, pics
        self.has_td = "tdx" in columns and "tdy" in columns
        self.scale = scale
        self.radians = radians
        self.zoom = scale if op == "scale" else 1.0  # lengths in pixels (size, Pose_Para scale) change by this
        self.zoom_cols = (
            [c for c in ("size", "scale") if c in columns and (c == "size" or pose_para)] if op == "scale" else []
        )
        self.mirror = bool(np.linalg.det(M) < 0)
        self.label_source = (
            "pitch,yaw,roll" + (" (checked against r00..r22)" if self.cross_check else "")
            if self.mode == "angles"
            else "r00..r22"
        )
        self.csv = src.kind == "csv"
        is_mat = path.is_dir() or path.suffix.lower() == ".mat"
        self.mat_base = (path if path.is_dir() else path.parent) if is_mat and "file" in columns else None

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
        from ..io.labels import batch_labels
        from ..rotation import frobenius

        n = batch.num_rows
        if self.stored_kind:  # rotation vectors, quaternions, 6-D, named columns: read as matrices
            from ..io import batch_rotations
            from ..rotation import soa as _soa

            X, _, reasons = batch_rotations(batch, self.in_system, self.mode, self.radians)
            return _soa.to_array(X, n), (reasons if reasons is not None else np.full(n, "", dtype=object))
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
        import pyarrow as pa

        from ..geometry.augment import augment_canonical, move_boxes, move_points, move_td
        from ..io import BBOX_COLS, LABEL_COLS, conversion_columns
        from ..io.images import row_ids
        from ..io.labels import numeric_column
        from ..io.readers import LINE_COL
        from ..rotation import canonical_to_labels

        lines = batch.column(LINE_COL).to_numpy()
        batch = batch.drop_columns([LINE_COL])
        n = batch.num_rows
        R, reasons = self.labels(batch)
        names = ids = None
        if self.pics is not None:
            names = [None if v is None else str(v) for v in batch.column(self.img_col).to_pylist()]
            ids = row_ids(
                batch.select([c for c in ("sequence", "camera", "frame") if c in batch.schema.names]).to_pandas()
            )
        wh, refs, size_reasons = row_sizes(batch, self.image_size, self.has_cols, self.pics, names, ids)
        reasons = np.where(reasons == "", size_reasons, reasons)
        extra = {}  # landmarks and boxes: NaN means missing and is kept; only non-numbers reject a row
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
        P, wh_out, scale_reasons = _pixel_transform(self.op, self.M, wh, self.crop, self.scale)
        reasons = np.where(reasons == "", scale_reasons, reasons)
        keep = reasons == ""
        kb = batch.filter(pa.array(keep)) if not keep.all() else batch
        A2 = augment_canonical(self.in_system.to_canonical(R[keep]), self.M)
        new = conversion_columns(canonical_to_labels(A2, self.system))
        Pk, out_k = P[keep], wh_out[keep]
        lm_new = None
        if self.n_lm:
            lm = np.stack([extra[c][keep] for c in self.lm_names], axis=-1).reshape(-1, self.n_lm, 2)
            lm_new = move_points(lm, Pk, self.mirror, self.perm)
            flat = lm_new.reshape(-1, 2 * self.n_lm)
            new.update({c: flat[:, i] for i, c in enumerate(self.lm_names)})
        boxes = 0
        if self.has_box:
            box = np.stack([extra[c][keep] for c in BBOX_COLS], axis=-1)
            box_new = move_boxes(box, Pk, self.M, out_k, lm_new, self.box_from, self.clip)
            boxes = int(np.isfinite(box_new).all(axis=1).sum())
            new.update({c: box_new[:, i] for i, c in enumerate(BBOX_COLS)})
        if self.has_td:
            new["tdx"], new["tdy"] = move_td(
                extra["tdx"][keep], extra["tdy"][keep], Pk, wh[keep, 1], out_k[:, 1], self.pose_para
            )
        for c in self.zoom_cols:
            new[c] = extra[c][keep] * self.zoom
        if self.has_cols:
            new["image_width"], new["image_height"] = out_k[:, 0].astype(np.int64), out_k[:, 1].astype(np.int64)
        out_cols, out_names = [], []
        for i, c in enumerate(kb.schema.names):
            out_names.append(c)
            out_cols.append(pa.array(new.pop(c)) if c in new else kb.column(i))
        for c in LABEL_COLS:
            if c in new:
                out_names.append(c)
                out_cols.append(pa.array(new.pop(c)))
        out = pa.RecordBatch.from_arrays(out_cols, names=out_names)
        A2_full = np.full((n, 3, 3), np.nan)
        A2_full[keep] = A2
        files = batch.column("file").to_pylist() if "file" in batch.schema.names else None
        return batch, lines, reasons, keep, out, boxes, (refs, names, P, wh, wh_out, A2_full, files)


def run_augment(
    input,
    output,
    system,
    image_size,
    op,
    angle,
    *,
    scheme="auto",
    box_from="auto",
    clip=False,
    images_dir=None,
    out_images=None,
    image_column=None,
    interpolation="linear",
    border="constant",
    jpeg_quality=95,
    rejects_path=None,
    overwrite=False,
    batch_size=65_536,
    bar=None,
    verbose=0,
    description="",
    workers=None,
    strict=False,
    crop=None,
    scale=None,
    images_optional=False,
    radians=False,
):
    """Augment a label table (and optionally its images). Returns a summary dict.

    ``image_size`` (``(W, H)`` or None) is checked against the table's ``image_width/image_height`` and the
    images; a row where two of them disagree is rejected. ``op = "crop"`` with ``crop = (x, y, w, h)`` cuts
    the images to that rectangle. Batches are transformed on ``workers`` threads (default: one per core, at
    most 8) while this thread reads, moves images and writes in order; at most ``workers + 1`` batches are in
    flight.
    ``images_optional``: ``images_dir`` is a ``.mat`` folder's own (not given by the user): an image found there
    gives (and checks) the row's size, a missing one is no reject.
    """

    from ..geometry.augment import plane_matrix
    from ..geometry.landmark_schemes import flip_permutation, scheme_for_count
    from ..io import BBOX_COLS, Rejects, TableWriter, check_output, open_table, system_metadata
    from ..io.rejects import fail_all_rejected
    from ..io.system_meta import output_system, resolve_system
    from ..io.transaction import ensure_transaction, staged_dir
    from .augment_images import ImageJob, RowImages
    from .inorder import in_order
    from .pools import default_threads

    path = Path(input)
    check_output(output, overwrite)
    src = open_table(path, batch_size, with_lines=True)
    res = resolve_system(src, system, option_is_output=True)  # the file's own system, else --system
    in_system, system = res.system, output_system(res)  # .mat Pose_Para is always 300w_lp; output in --system
    columns = src.columns
    n_lm, perm, lm_text = _plan_landmarks(path, columns, scheme, op)
    box_present = [c for c in BBOX_COLS if c in columns]
    if box_present and len(box_present) != 4:
        raise HpeError(f"{path}: expected all of {', '.join(BBOX_COLS)}, got only {', '.join(box_present)}")
    has_cols = _size_source(columns, image_size, images_dir, path)
    img_col = _image_column(path, columns, images_dir, out_images, image_column)
    M = plane_matrix(op, angle) if op not in ("crop", "scale") else np.eye(2)
    mat_input = (
        bool(getattr(src, "dataset", False))
        and (path.is_dir() or path.suffix.lower() == ".mat")
        and out_images is not None
    )
    pose_para = (path.is_dir() or path.suffix.lower() == ".mat") or {"tdz", "scale"} <= set(columns)
    plan = _Plan(
        path,
        src,
        in_system,
        system,
        columns,
        n_lm,
        perm,
        bool(box_present),
        M,
        op,
        crop,
        image_size,
        has_cols,
        box_from,
        clip,
        pose_para,
        img_col,
        RowImages(images_dir, images_optional) if images_dir else None,
        scale=scale,
        radians=radians,
    )
    rejects = Rejects(rejects_path, overwrite, strict=strict, source=None if plan.mat_base is not None else src)
    meta = {
        **system_metadata(system),
        "hpe:augment": {
            "op": op,
            "angle_deg": angle,
            "crop": list(crop) if crop else None,
            "scale": scale,
            "description": description,
            "image_size": list(image_size) if image_size else "from image_width/image_height or the images",
            "landmarks": lm_text,
            "box_from": box_from,
            "clip": clip,
            "pixel_convention": "pixel centres at integer coordinates; centre ((W-1)/2, (H-1)/2)",
        },
    }
    counts = {"rows": 0, "written": 0, "boxes": 0}
    workers = default_threads(workers)  # --threads; one per core (at most 8) by default
    if bar is not None and src.num_rows is not None:
        bar.total = src.num_rows
        getattr(bar, "refresh", lambda: None)()

    def perm_of(n):
        name = scheme_for_count(n)
        return None if name is None else flip_permutation(name)

    with ensure_transaction(), contextlib.ExitStack() as stack:
        job = None
        if out_images is not None:
            stage = stack.enter_context(staged_dir(out_images, overwrite))
            job = ImageJob(
                stage,
                Path(out_images),
                interpolation,
                border,
                jpeg_quality,
                overwrite,
                mat_dir=path if mat_input else None,
                perm_of=perm_of,
            )
        writer = stack.enter_context(TableWriter(output, overwrite, meta))

        def finish(_, read_rejects, future):
            _finish_batch(read_rejects, future.result(), rejects, job, writer, counts, bar, plan)

        in_order(_batches_or_empty(src), plan.work, finish, workers)
        rejects.check()  # without --rejects (or with --strict) any bad row fails the run: nothing is written
        if counts["rows"] and not counts["written"]:  # the rejects file is still written: it says why
            fail_all_rejected(
                rejects,
                f"{path}: nothing augmented: all {counts['rows']} row(s) rejected "
                f"({rejects.first_where or 'see the rejects file'})",
            )
        rejects.finish()
    box_text = f"{counts['boxes']} moved ({box_from}{', clipped' if clip else ''})" if box_present else "none in input"
    return {
        "system": system.name,
        "rows": counts["rows"],
        "written": counts["written"],
        "label_source": plan.label_source,
        "landmarks": lm_text,
        "boxes": box_text,
        "images": len(job.done) if job else 0,
        "mats": job.mats if job else 0,
        "rejects": dict(rejects.counts),
    }


def _finish_batch(read_rejects, result, rejects, job, writer, counts, bar, plan):
    """On the main thread, in input order: rejects, images, the table."""
    batch, lines, reasons, keep, out, boxes, extra = result
    rejects.add_unreadable(read_rejects)
    counts["rows"] += len(read_rejects)
    if not keep.all():
        drop = ~keep
        cols = {c: batch.column(i).to_numpy(zero_copy_only=False)[drop] for i, c in enumerate(batch.schema.names)}
        if plan.mat_base is not None:  # a .mat file is one record: named by its file, as the messages do
            cols["file"] = np.array([plan.where(0, f) for f in cols["file"]], dtype=object)
            if rejects.first_where is None:
                rejects.first_where = f"{cols['file'][0]}: {reasons[drop][0]}"
        else:
            cols = {"row": plan.numbers(lines[drop]), **cols}
        rejects.add(cols, reasons[drop], lines=lines[drop] if plan.csv else None)
    if job is not None:
        refs, names, P, wh_in, wh_out, A2, files = extra
        rows = []
        for i in np.flatnonzero(keep):
            mat = None
            if job.mat_dir is not None and files is not None:
                base = job.mat_dir if job.mat_dir.is_dir() else job.mat_dir.parent
                mat = (base / files[i], A2[i], plan.roi_fn, plan.zoom)
            rows.append(
                (
                    names[i] or "",
                    plan.where(lines[i], files[i] if files else None),
                    refs[i],
                    P[i],
                    wh_in[i],
                    wh_out[i],
                    plan.mirror,
                    mat,
                )
            )
        # the image work is the slow part: move the bar per row as its picture is done
        job.add_rows(rows, tick=bar.update if bar is not None else None)
    writer.write(out)
    counts["boxes"] += boxes
    counts["rows"] += batch.num_rows
    counts["written"] += int(keep.sum())
    if bar is not None:
        bar.update(batch.num_rows - (int(keep.sum()) if job is not None else 0))
