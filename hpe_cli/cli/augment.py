"""``hpe augment``: rotate or mirror a labelled dataset (labels, landmarks, boxes, images)."""
from __future__ import annotations

from pathlib import Path

import click

from .options import (batch_option, echo_summary, output_option, overwrite_option, progress, rejects_option,
                      system_option, verbosity_options)

#: columns tried, in order, for the image file name when --image-column is not given
IMAGE_COLUMNS = ("image", "image_path", "img_path", "file_name", "filename", "file", "path")
_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
#: rows whose angles and r00..r22 disagree by more than this (Frobenius) are rejected
AGREE_TOL = 1e-3


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@output_option()
@system_option()
@click.option("--image-size", nargs=2, type=click.IntRange(1), required=True, metavar="W H",
              help="Width and height of the images, in pixels.")
@click.option("--hflip", is_flag=True, help="Mirror left-right (with --vflip: both, a rotation by 180).")
@click.option("--vflip", is_flag=True, help="Mirror top-bottom.")
@click.option("--rotate", type=float, metavar="DEG",
              help="Rotate counter-clockwise on screen by DEG degrees about the image centre (OpenCV's sign).")
@click.option("--mirror-line", type=float, metavar="DEG",
              help="Mirror about the line through the image centre at DEG degrees counter-clockwise from the "
                   "horizontal (90 = --hflip, 0 = --vflip).")
@click.option("--landmarks", "scheme", type=click.Choice(["auto", "ibug68", "face70", "aflw21", "none"]),
              default="auto", show_default=True,
              help="Left/right scheme of the lm{i}_x/lm{i}_y columns, re-indexed after a mirror. auto: by count "
                   "(68, 70, 21). none: leave the landmark columns unchanged.")
@click.option("--box-from", type=click.Choice(["auto", "landmarks", "corners"]), default="auto", show_default=True,
              help="New box: the moved corners (exact for flips and 90-degree turns), or the box of the moved "
                   "landmarks. auto: corners when exact, else landmarks, else corners.")
@click.option("--clip", is_flag=True, help="Clip boxes to the pixel centres [0, W-1] x [0, H-1].")
@click.option("--images", "images_dir", type=click.Path(exists=True, file_okay=False),
              help="Folder of the input images (names from the image column, relative to it).")
@click.option("--out-images", "out_images", type=click.Path(file_okay=False),
              help="Folder for the transformed images (same relative names); created if missing.")
@click.option("--image-column", help=f"Column with image file names. Default: the first of {', '.join(IMAGE_COLUMNS)}; "
                                     "a .mat name is matched to the image with the same stem.")
@click.option("--interpolation", type=click.Choice(["linear", "cubic", "nearest", "area", "lanczos"]),
              default="linear", show_default=True, help="Resampling for rotations and oblique mirrors.")
@click.option("--border", type=click.Choice(["constant", "replicate", "reflect", "reflect101", "wrap"]),
              default="constant", show_default=True, help="Fill of pixels that come from outside the image.")
@click.option("--jpeg-quality", type=click.IntRange(1, 100), default=95, show_default=True)
@rejects_option
@overwrite_option
@batch_option
@verbosity_options
def augment(input, output, system, image_size, hflip, vflip, rotate, mirror_line, scheme, box_from, clip, images_dir,
            out_images, image_column, interpolation, border, jpeg_quality, rejects, overwrite, batch_size, verbose,
            quiet):
    """Rotate or mirror a head-pose dataset: labels, landmarks, boxes and images.

    INPUT is a .parquet/.csv label table (or a folder of .mat files) with
    angle columns pitch,yaw,roll (degrees) or, when it has none, matrix
    columns r00..r22 (the stored matrix of --system); rows where both are
    present and disagree are rejected. Labels are moved
    exactly (SPEC §5): A' = M A for a rotation, A' = M A diag(-1,1,1) for a
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
    Images keep their size; rotated corners are filled per --border.

    \b
    Examples:
      hpe augment labels.parquet -o flipped.parquet --image-size 450 450 --hflip
      hpe augment labels.csv -o rot30.csv --system 6drepnet --image-size 640 480 --rotate 30
      hpe augment AFLW2000/ -o rot.parquet --image-size 450 450 --rotate -15 --images AFLW2000/ --out-images rot/
      hpe augment aflw_lm.parquet -o aflw_v.parquet --image-size 450 450 --vflip --landmarks aflw21
      hpe augment labels.parquet -o m20.parquet --image-size 450 450 --mirror-line 20 --clip
      hpe augment labels.parquet -o both.parquet --image-size 450 450 --hflip --vflip
    """
    chosen = [name for name, on in (("--hflip", hflip), ("--vflip", vflip), ("--rotate", rotate is not None),
                                    ("--mirror-line", mirror_line is not None)) if on]
    if not chosen:
        raise click.UsageError("expected one of --hflip, --vflip, --rotate DEG, --mirror-line DEG; got none")
    if len(chosen) > 1 and sorted(chosen) != ["--hflip", "--vflip"]:
        raise click.UsageError(f"expected one augmentation (or --hflip with --vflip), got {' and '.join(chosen)}")
    if hflip and vflip:
        op, angle, desc = "hvflip", None, "hflip+vflip (rotation by 180)"
    elif hflip or vflip:
        op, angle, desc = ("hflip" if hflip else "vflip"), None, "hflip" if hflip else "vflip"
    elif rotate is not None:
        op, angle, desc = "rotate", rotate, f"rotate {rotate:g} deg counter-clockwise"
    else:
        op, angle, desc = "mirror", mirror_line, f"mirror about the {mirror_line:g} deg line"
    for name, v in (("--rotate", rotate), ("--mirror-line", mirror_line)):
        if v is not None and not abs(v) < float("inf"):
            raise click.BadParameter(f"expected a finite angle in degrees, got {v}", param_hint=name)
    if (images_dir is None) != (out_images is None):
        raise click.UsageError("--images and --out-images go together")
    bar = progress(desc="augment", quiet=quiet)
    try:
        s = run_augment(input, output, system, tuple(image_size), op, angle, scheme=scheme, box_from=box_from,
                        clip=clip, images_dir=images_dir, out_images=out_images, image_column=image_column,
                        interpolation=interpolation, border=border, jpeg_quality=jpeg_quality, rejects_path=rejects,
                        overwrite=overwrite, batch_size=batch_size, bar=bar, verbose=verbose, description=desc)
    finally:
        bar.close()
    lines = [f"{s['written']} of {s['rows']} rows augmented ({desc}) in {system.name} -> {output}",
             f"landmarks: {s['landmarks']}; boxes: {s['boxes']}"]
    if verbose:
        lines.append(f"labels read from {s['label_source']}; pixel centres at integers, "
                     f"image centre ({(image_size[0] - 1) / 2:g}, {(image_size[1] - 1) / 2:g})")
    if images_dir is not None:
        lines.append(f"images: {s['images']} written -> {out_images}")
    if s["rejects"]:
        lines.append("rejected: " + "; ".join(f"{n} {r}" for r, n in sorted(s["rejects"].items(), key=lambda x: -x[1]))
                     + (f" -> {rejects}" if rejects else " (use --rejects FILE to keep them)"))
    echo_summary(lines, quiet)


# ----------------------------------------------------------------------------------------------------- pipeline
def _batches_or_empty(src):
    """The input's batches; one empty batch for an empty table, so the output still gets its columns."""
    import pyarrow as pa

    any_batch = False
    for batch in src.batches():
        any_batch = True
        yield batch
    if not any_batch:
        yield pa.RecordBatch.from_pydict({f.name: pa.array([], type=f.type) for f in src.schema}, schema=src.schema)


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
        where = f"{self.path}: row {row}"
        if not _safe_relative(name):
            raise HpeError(f"{where}: expected an image name relative to --images, got {name!r}")
        src = _find_image(self.src, name)
        if src is None:
            raise HpeError(f"{where}: no image for {name!r} in {self.src}")
        rel = src.relative_to(self.src)
        final = self.dst / rel
        if final.exists() and not self.overwrite:
            raise HpeError(f"{final}: already exists (use --overwrite to replace it)")
        img = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise HpeError(f"{where}: {src}: not a readable image")
        h, w = img.shape[:2]
        if (w, h) != tuple(self.size):
            raise HpeError(f"{where}: {src} is {w}x{h}, expected --image-size {self.size[0]} {self.size[1]}")
        out = warp_image(img, self.M, self.interp, self.border)
        staged = self.stage / rel
        staged.parent.mkdir(parents=True, exist_ok=True)
        params = [cv2.IMWRITE_JPEG_QUALITY, self.quality] if src.suffix.lower() in (".jpg", ".jpeg") else []
        if not cv2.imwrite(str(staged), out, params):
            raise HpeError(f"{staged}: could not write image")
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
                jpeg_quality=95, rejects_path=None, overwrite=False, batch_size=262_144, bar=None, verbose=0,
                description=""):
    """Augment a label table (and optionally its images). Returns a summary dict."""
    import numpy as np
    import pyarrow as pa

    from ..errors import HpeError
    from ..geometry.augment import augment_boxes, augment_canonical, augment_points, plane_matrix
    from ..io import (BBOX_COLS, LABEL_COLS, MATRIX_COLS, Rejects, TableWriter, check_output, conversion_columns,
                      landmark_cols, open_table, system_metadata)
    from ..io.labels import batch_labels, label_mode, numeric_column
    from ..rotation import canonical_to_labels, frobenius

    path = Path(input)
    check_output(output, overwrite)
    src = open_table(path, batch_size)
    columns = src.columns
    mode = label_mode(columns, path, system)  # the system's own columns, else angles, else r00..r22
    stored_kind = mode not in ("angles", "matrix") or (system.columns and all(c in columns for c in
                                                                               system.value_columns))
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
    rejects = Rejects(rejects_path, overwrite)
    meta = {**system_metadata(system), "hpe:augment": {
        "op": op, "angle_deg": angle, "description": description, "image_size": list(image_size),
        "landmarks": lm_text, "box_from": box_from, "clip": clip,
        "pixel_convention": "pixel centres at integer coordinates; centre ((W-1)/2, (H-1)/2)"}}
    job = None
    if images_dir is not None:
        job = _ImageJob(images_dir, out_images, M, image_size, interpolation, border, jpeg_quality, overwrite, path)
    rows = written = n_boxes = n_images = 0
    try:
        with TableWriter(output, overwrite, meta) as writer:
            for batch in _batches_or_empty(src):
                n = batch.num_rows
                if stored_kind:  # rotation vectors, quaternions, 6-D, named columns: read as matrices
                    from ..io import batch_rotations
                    from ..rotation import soa as _soa

                    X, _, reasons = batch_rotations(batch, system, mode)
                    values = _soa.to_array(X, n)
                    reasons = reasons if reasons is not None else np.full(n, "", dtype=object)
                else:
                    values, reasons = batch_labels(batch, mode)
                if mode == "angles" and not stored_kind:
                    R = system.from_angles(np.where(np.isfinite(values), values, 0.0))
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
                if not keep.all():
                    drop = ~keep
                    rejects.add({c: batch.column(i).to_numpy(zero_copy_only=False)[drop]
                                 for i, c in enumerate(batch.schema.names)},
                                reasons[drop])
                kb = batch.filter(pa.array(keep)) if not keep.all() else batch
                A2 = augment_canonical(system.to_canonical(R[keep]), M)
                new = conversion_columns(canonical_to_labels(A2, system))
                lm_new = None
                if n_lm:
                    lm = np.stack([extra[c][keep] for c in lm_names], axis=-1).reshape(-1, n_lm, 2)
                    lm_new = augment_points(lm, M, image_size, perm)
                    flat = lm_new.reshape(-1, 2 * n_lm)
                    new.update({c: flat[:, i] for i, c in enumerate(lm_names)})
                if has_box:
                    box = np.stack([extra[c][keep] for c in BBOX_COLS], axis=-1)
                    box_new = augment_boxes(box, M, image_size, lm_new, box_from, clip)
                    n_boxes += int(np.isfinite(box_new).all(axis=1).sum())
                    new.update({c: box_new[:, i] for i, c in enumerate(BBOX_COLS)})
                if job is not None:
                    names = kb.column(kb.schema.get_field_index(img_col)).to_pylist()
                    orig = np.flatnonzero(keep)
                    for i, name in enumerate(names):
                        if name is None:
                            raise HpeError(f"{path}: row {rows + orig[i]}: empty {img_col}")
                        job.add(str(name), rows + orig[i])
                out_cols, out_names = [], []
                for i, c in enumerate(kb.schema.names):
                    out_names.append(c)
                    out_cols.append(pa.array(new.pop(c)) if c in new else kb.column(i))
                for c in LABEL_COLS:
                    if c in new:
                        out_names.append(c)
                        out_cols.append(pa.array(new.pop(c)))
                writer.write(pa.RecordBatch.from_arrays(out_cols, names=out_names))
                rows += n
                written += int(keep.sum())
                if bar is not None:
                    bar.update(n)
            if job is not None:
                n_images = len(job.done)
                job.commit()
                job = None
    except BaseException:
        if job is not None:
            job.cleanup()
        raise
    rejects.write()
    box_text = f"{n_boxes} moved ({box_from}{', clipped' if clip else ''})" if has_box else "none in input"
    label_source = "pitch,yaw,roll" + (" (checked against r00..r22)" if cross_check else "") \
        if mode == "angles" else "r00..r22"
    return {"rows": rows, "written": written, "label_source": label_source, "landmarks": lm_text, "boxes": box_text,
            "images": n_images, "rejects": dict(rejects.counts)}
