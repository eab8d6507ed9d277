"""``hpe augment`` as a streaming job: read batches, move labels/landmarks/boxes (and images), write."""
from __future__ import annotations

from pathlib import Path

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
        yield pa.RecordBatch.from_pydict({f.name: pa.array([], type=f.type) for f in src.schema},
                                         schema=src.schema), []


def _is_numeric_type(t) -> bool:
    import pyarrow as pa

    return pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_decimal(t) or pa.types.is_null(t) \
        or pa.types.is_boolean(t)


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
            raise HpeError(f"{path}: {n} landmarks (lm0_x..lm{n - 1}_y) match no built-in scheme "
                           f"(ibug68, face70, aflw21), and a mirror must re-index them; "
                           "use --landmarks none to leave them unchanged")
        return n, (None if name is None else flip_permutation(name)), \
            f"{n} moved" + (f", scheme {name}" if name else "")
    want = SCHEMES[scheme].size
    if n != want:
        raise HpeError(f"{path}: --landmarks {scheme} expects {want} landmark column pairs lm0_x..lm{want - 1}_y, "
                       f"got {n}")
    return n, flip_permutation(scheme), f"{n} moved, scheme {scheme}"


def _find_image(images_dir: Path, name: str):
    """The image for a table entry: the path itself, or the same stem with an image suffix."""
    p = images_dir / name
    if p.suffix.lower() in _IMAGE_SUFFIXES and p.is_file():
        return p
    for suf in _IMAGE_SUFFIXES:
        for cand in (p.with_suffix(suf), p.with_suffix(suf.upper())):
            if cand.is_file():
                return cand
    return None


def _safe_relative(name: str) -> bool:
    p = Path(name)
    return bool(name) and not p.is_absolute() and ".." not in p.parts


class _ImageJob:
    """Warp images into a staging folder; move them into place only when everything succeeded."""

    def __init__(self, images_dir, out_dir, M, image_size, interpolation, border, jpeg_quality, overwrite, path):
        import tempfile

        from ..errors import HpeError

        self.src, self.dst = Path(images_dir), Path(out_dir)
        if self.dst.exists() and self.dst.resolve() == self.src.resolve():
            raise HpeError(f"{out_dir}: --out-images must differ from --images (inputs are never modified)")
        if not self.dst.parent.exists():
            raise HpeError(f"{out_dir}: folder {self.dst.parent} does not exist")
        self.created = not self.dst.exists()
        self.dst.mkdir(exist_ok=True)
        self.stage = Path(tempfile.mkdtemp(prefix=".hpe-augment-", dir=self.dst))
        self.M, self.size, self.interp, self.border = M, image_size, interpolation, border
        self.quality, self.overwrite, self.path = jpeg_quality, overwrite, path
        self.done: dict = {}

    def add(self, name: str, row: int):
        import cv2

        from ..errors import HpeError
        from ..geometry.image_ops import warp_image

        if name in self.done:
            return
        where = self.path(row) if callable(self.path) else f"{self.path}: row {row}"  # TableSource.where
        if not _safe_relative(name):
            raise HpeError(f"{where}: expected an image name relative to --images, got {name!r}")
        src = _find_image(self.src, name)
        if src is None:
            raise HpeError(f"{where}: no image for {name!r} in {self.src}")
        rel = src.relative_to(self.src)
        final = self.dst / rel
        if final.exists() and not self.overwrite:
            raise HpeError(f"{final}: already exists (use --overwrite to replace it)")
        import numpy as np

        try:  # through bytes: OpenCV's own file functions fail on names that are not UTF-8
            img = cv2.imdecode(np.fromfile(src, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        except OSError:
            img = None
        if img is None:
            raise HpeError(f"{where}: {src}: not a readable image")
        h, w = img.shape[:2]
        if (w, h) != tuple(self.size):
            raise HpeError(f"{where}: {src} is {w}x{h}, expected --image-size {self.size[0]} {self.size[1]}")
        out = warp_image(img, self.M, self.interp, self.border)
        staged = self.stage / rel
        staged.parent.mkdir(parents=True, exist_ok=True)
        params = [cv2.IMWRITE_JPEG_QUALITY, self.quality] if src.suffix.lower() in (".jpg", ".jpeg") else []
        ok, buf = cv2.imencode(src.suffix.lower() or ".png", out, params)
        if not ok:
            raise HpeError(f"{final}: could not encode the image as {src.suffix or 'PNG'}")
        buf.tofile(staged)
        self.done[name] = rel

    def commit(self):
        import os

        for rel in self.done.values():
            (self.dst / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.stage / rel, self.dst / rel)
        self.cleanup(failed=False)

    def cleanup(self, failed: bool = True):
        import shutil

        shutil.rmtree(self.stage, ignore_errors=True)
        if failed and self.created:
            try:
                self.dst.rmdir()
            except OSError:
                pass


def run_augment(input, output, system, image_size, op, angle, *, scheme="auto", box_from="auto", clip=False,
                images_dir=None, out_images=None, image_column=None, interpolation="linear", border="constant",
                jpeg_quality=95, rejects_path=None, overwrite=False, batch_size=65_536, bar=None, verbose=0,
                description="", workers=None, strict=False):
    """Augment a label table (and optionally its images). Returns a summary dict.

    Batches are transformed on ``workers`` threads (default: up to 2) while
    this thread reads, moves images and writes in order, as ``hpe convert``
    does; at most ``workers + 1`` batches are in flight.
    """
    import os

    import numpy as np
    import pyarrow as pa

    from ..errors import HpeError
    from ..geometry.augment import augment_boxes, augment_canonical, augment_points, plane_matrix
    from ..io import (BBOX_COLS, LABEL_COLS, MATRIX_COLS, Rejects, TableWriter, check_output, conversion_columns,
                      landmark_cols, open_table, system_metadata)
    from ..io.labels import batch_labels, label_mode, numeric_column
    from ..rotation import canonical_to_labels, frobenius
    from .inorder import in_order

    path = Path(input)
    check_output(output, overwrite)
    from ..io.readers import LINE_COL

    src = open_table(path, batch_size, with_lines=True)
    from ..io.system_meta import output_system, resolve_system

    res = resolve_system(src, system, option_is_output=True)  # the file's own system, else --system
    in_system, system = res.system, output_system(res)  # .mat Pose_Para is always 300w_lp; output in --system
    columns = src.columns
    mode = label_mode(columns, path, in_system)  # the system's own columns, else angles, else r00..r22
    stored_kind = mode not in ("angles", "matrix") or bool(in_system.columns and all(c in columns for c in
                                                                                     in_system.value_columns))
    cross_check = mode == "angles" and not stored_kind and all(c in columns for c in MATRIX_COLS)
    n_lm, perm, lm_text = _plan_landmarks(path, columns, scheme, op)
    lm_names = landmark_cols(n_lm)
    box_present = [c for c in BBOX_COLS if c in columns]
    if box_present and len(box_present) != 4:
        raise HpeError(f"{path}: expected all of {', '.join(BBOX_COLS)}, got only {', '.join(box_present)}")
    has_box = bool(box_present)
    img_col = None
    if images_dir is not None:
        img_col = image_column or next((c for c in IMAGE_COLUMNS if c in columns), None)
        if img_col is None or img_col not in columns:
            raise HpeError(f"{path}: expected an image column ({image_column or ', '.join(IMAGE_COLUMNS)}) "
                           "to go with --images, got none")
    elif image_column is not None:
        raise HpeError("--image-column needs --images and --out-images")
    M = plane_matrix(op, angle)
    rejects = Rejects(rejects_path, overwrite, strict=strict, source=src)
    meta = {**system_metadata(system), "hpe:augment": {
        "op": op, "angle_deg": angle, "description": description, "image_size": list(image_size),
        "landmarks": lm_text, "box_from": box_from, "clip": clip,
        "pixel_convention": "pixel centres at integer coordinates; centre ((W-1)/2, (H-1)/2)"}}
    job = None
    if images_dir is not None:
        job = _ImageJob(images_dir, out_images, M, image_size, interpolation, border, jpeg_quality, overwrite,
                        src.where)
    rows = written = n_boxes = n_images = 0
    workers = workers or min(2, os.cpu_count() or 1)
    try:
        def work(batch):  # on a worker thread: labels, landmarks and boxes of one batch
            lines = batch.column(LINE_COL).to_numpy()
            batch = batch.drop_columns([LINE_COL])
            n = batch.num_rows
            if stored_kind:  # rotation vectors, quaternions, 6-D, named columns: read as matrices
                from ..io import batch_rotations
                from ..rotation import soa as _soa

                X, _, reasons = batch_rotations(batch, in_system, mode)
                values = _soa.to_array(X, n)
                reasons = reasons if reasons is not None else np.full(n, "", dtype=object)
            else:
                values, reasons = batch_labels(batch, mode)
            if mode == "angles" and not stored_kind:
                R = in_system.from_angles(np.where(np.isfinite(values), values, 0.0))
                if cross_check:  # a table with both must agree, or which one is the label?
                    R_in, r_in = batch_labels(batch, "matrix")
                    reasons = np.where(reasons == "", r_in, reasons)
                    ok = reasons == ""
                    gap = np.zeros(n)
                    gap[ok] = frobenius(R[ok], R_in[ok])
                    reasons[ok & (gap > AGREE_TOL)] = "angles and r00..r22 disagree"
            else:
                R = values
            # landmarks and boxes: NaN means missing and is kept; only non-numbers reject a row
            extra = {}
            for c in lm_names + (BBOX_COLS if has_box else []):
                v, r = numeric_column(batch, c)
                extra[c] = v
                if not _is_numeric_type(batch.schema.field(c).type):  # only text can hold non-numbers
                    bad = np.char.startswith(r.astype(str), "non-numeric")
                    reasons = np.where((reasons == "") & bad, r, reasons)
            keep = reasons == ""
            kb = batch.filter(pa.array(keep)) if not keep.all() else batch
            A2 = augment_canonical(in_system.to_canonical(R[keep]), M)
            new = conversion_columns(canonical_to_labels(A2, system))
            lm_new = None
            boxes = 0
            if n_lm:
                lm = np.stack([extra[c][keep] for c in lm_names], axis=-1).reshape(-1, n_lm, 2)
                lm_new = augment_points(lm, M, image_size, perm)
                flat = lm_new.reshape(-1, 2 * n_lm)
                new.update({c: flat[:, i] for i, c in enumerate(lm_names)})
            if has_box:
                box = np.stack([extra[c][keep] for c in BBOX_COLS], axis=-1)
                box_new = augment_boxes(box, M, image_size, lm_new, box_from, clip)
                boxes = int(np.isfinite(box_new).all(axis=1).sum())
                new.update({c: box_new[:, i] for i, c in enumerate(BBOX_COLS)})
            out_cols, out_names = [], []
            for i, c in enumerate(kb.schema.names):
                out_names.append(c)
                out_cols.append(pa.array(new.pop(c)) if c in new else kb.column(i))
            for c in LABEL_COLS:
                if c in new:
                    out_names.append(c)
                    out_cols.append(pa.array(new.pop(c)))
            out = pa.RecordBatch.from_arrays(out_cols, names=out_names)
            return batch, lines, reasons, keep, kb, out, boxes

        def finish(_, read_rejects, future):
            nonlocal rows, written, n_boxes
            if read_rejects:
                read_lines = np.array([r.line for r in read_rejects], dtype=np.int64)
                rejects.add({"row": read_lines, "raw": np.array([r.raw for r in read_rejects], dtype=object)},
                            [r.reason for r in read_rejects], lines=read_lines)
                rows += len(read_rejects)
            batch, lines, reasons, keep, kb, out, boxes = future.result()
            n = batch.num_rows
            if not keep.all():
                drop = ~keep
                rejects.add({"row": lines[drop], **{c: batch.column(i).to_numpy(zero_copy_only=False)[drop]
                                                    for i, c in enumerate(batch.schema.names)}},
                            reasons[drop], lines=lines[drop])
            if job is not None:
                names = kb.column(kb.schema.get_field_index(img_col)).to_pylist()
                orig = np.flatnonzero(keep)
                for i, name in enumerate(names):
                    if name is None:
                        raise HpeError(f"{src.where(lines[orig[i]])}: empty {img_col}")
                    job.add(str(name), int(lines[orig[i]]))
            writer.write(out)
            n_boxes += boxes
            rows += n
            written += int(keep.sum())
            if bar is not None:
                bar.update(n)

        with TableWriter(output, overwrite, meta) as writer:
            in_order(_batches_or_empty(src), work, finish, workers)
            rejects.check()  # without --rejects (or with --strict) any bad row fails the run: nothing is written
            if job is not None:
                n_images = len(job.done)
                job.commit()
                job = None
    except BaseException:
        if job is not None:
            job.cleanup()
        raise
    rejects.finish()
    box_text = f"{n_boxes} moved ({box_from}{', clipped' if clip else ''})" if has_box else "none in input"
    label_source = "pitch,yaw,roll" + (" (checked against r00..r22)" if cross_check else "") \
        if mode == "angles" else "r00..r22"
    return {"system": system.name, "rows": rows, "written": written, "label_source": label_source, "landmarks": lm_text, "boxes": box_text,
            "images": n_images, "rejects": dict(rejects.counts)}
