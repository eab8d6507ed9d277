"""``hpe draw``: draw pose axes or a pose cube onto images (or blank canvases)."""
from __future__ import annotations

import click

from ..io.columns import column_options

from .options import SYSTEM, echo_summary, overwrite_option, progress, rejects_option, verbosity_options

#: 300W-LP/AFLW2000 Pose_Para: line length = this many Basel-Face-Model units times ``scale``.
#: The model is in micrometres and its origin is the centre of the head (the nose tip is
#: about 130 mm in front of it, the outer eye corners 43 mm to each side).
MAT_LENGTH_UNITS = 100_000.0
#: when a row gives no size: line length as a fraction of min(image width, height)
DEFAULT_LENGTH_FRACTION = 0.25
_WRITABLE = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"}


def _canvas_size(ctx, param, value):
    if value is None:
        return None
    try:
        w, h = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected WIDTHxHEIGHT such as 640x480, got {value!r}") from None
    if not (1 <= w <= 20000 and 1 <= h <= 20000):
        raise click.BadParameter(f"expected sizes between 1 and 20000 pixels, got {value!r}")
    return w, h


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@click.option("-o", "--output", "outdir", type=click.Path(file_okay=False), required=True,
              help="Output folder (created if missing); images keep their relative names.")
@click.option("--images", type=click.Path(exists=True, file_okay=False),
              help="Folder the `image` column is relative to (default: INPUT's folder).")
@click.option("--system", "system", type=SYSTEM, default="300w_lp", show_default=True,
              help="Rotation system of the labels: a built-in name (see `hpe systems`) or a .toml file.")
@click.option("--style", type=click.Choice(["axes", "cube"]), default="axes", show_default=True,
              help="Three axis lines (Hopenet's draw_axis) or the pose cube.")
@click.option("--canvas", type=str, callback=_canvas_size, metavar="WxH",
              help="Draw on blank WxH canvases instead of reading images.")
@click.option("--radians", is_flag=True, help="INPUT angle columns are in radians.")
@click.option("--columns", "use", type=click.Choice(["auto", "angles", "matrix"]), default="auto",
              show_default=True, help="Draw from pitch,yaw,roll or r00..r22 (auto: angles when present).")
@click.option("--length", type=click.FloatRange(0, min_open=True),
              help="Line length in pixels for every face (overrides bbox_h/2, size and scale).")
@click.option("--thickness", type=click.IntRange(1, 50), help="Line thickness in pixels (default: from the length).")
@click.option("--tdy-origin", type=click.Choice(["auto", "top", "bottom"]), default="auto", show_default=True,
              help="tdy is measured from the image top (pixel row) or from the bottom row (300W-LP Pose_Para: "
                   "row = height - 1 - tdy). auto: bottom for .mat input or tables with tdz and scale columns.")
@click.option("--annotate", is_flag=True, help="Write the angles (in --system) above each face.")
@click.option("--grid", is_flag=True, help="Write contact sheets (contact_sheet_001.png, ...) instead of images.")
@click.option("--grid-cols", type=click.IntRange(1, 64), default=6, show_default=True,
              help="Tiles per row (a sheet holds cols x cols tiles).")
@click.option("--tile", type=click.IntRange(32, 2048), default=256, show_default=True, help="Tile size, pixels.")
@click.option("--limit", type=click.IntRange(1), help="Draw at most this many images.")
@rejects_option
@overwrite_option
@verbosity_options
@column_options
def draw(input, outdir, images, system, style, canvas, radians, use, length, thickness, tdy_origin, annotate,
         grid, grid_cols, tile, limit, rejects, overwrite, verbose, quiet):
    """Draw head poses onto their images.

    INPUT is a .parquet or .csv label table (angles pitch,yaw,roll in degrees,
    or matrices r00..r22 in --system) with an `image` column, or a folder of
    300W-LP/AFLW2000 .mat files (image = the same name with .jpg). Each image
    is drawn once with all its rows and written to OUTDIR under the same
    relative name.

    The drawing uses only the matrix, mapped to the canonical 300W-LP frame,
    so it is right for every system and for yaw beyond +-90. Lines start at
    the head centre: red (BGR 0,0,255) points to the subject's left, green
    (0,255,0) from forehead to chin, blue (255,0,0) out of the nose. The cube
    has a red back square, blue edges along the nose and a green face-front
    square; hidden edges are dashed, so a face turned away shows its green
    square dashed behind the red one.

    \b
    Centre and length, per row (first that is present):
      bbox_x,bbox_y,bbox_w,bbox_h  centre of the box, length bbox_h/2
      tdx,tdy[,size]               centre (tdx, tdy), length `size`;
                                   with tdz,scale (Pose_Para) length
                                   100000*scale and tdy from the bottom
      nothing                      image centre, length min(W,H)/4

    \b
    Examples:
      hpe draw AFLW2000/ -o drawn/
      hpe draw labels.parquet -o drawn/ --images 300W_LP/ --style cube
      hpe draw preds.csv -o drawn/ --images frames/ --system 6drepnet --columns matrix
      hpe draw poses.csv -o canvas/ --canvas 640x480 --annotate
      hpe draw AFLW2000/ -o sheet/ --grid --grid-cols 4 --annotate
    """
    bar = progress(desc="draw", quiet=quiet, unit="images")
    try:
        s = run_draw(input, outdir, images=images, system=system, style=style, canvas=canvas, radians=radians,
                     use=use, length=length, thickness=thickness, tdy_origin=tdy_origin, annotate=annotate,
                     grid=grid, grid_cols=grid_cols, tile=tile, limit=limit, rejects_path=rejects,
                     overwrite=overwrite, progress=bar)
    finally:
        bar.close()
    lines = [f"drew {s['faces']} faces ({style}) on {s['images']} {'canvases' if canvas else 'images'} -> "
             + (f"{s['sheets']} contact sheet(s) in {outdir}" if grid else str(outdir))]
    if s["rejects"]:
        lines.append("rejected: " + "; ".join(f"{n} {r}" for r, n in s["rejects"].items())
                     + (f" -> {rejects}" if rejects else ""))
    echo_summary(lines, quiet)


def _read_all(src, mode, radians, system):
    """Whole table as (frame, canonical A, angles for captions in ``system``, reasons).

    A dataset reader's labels (.mat Pose_Para: always 300w_lp) are read in
    the dataset's own system and only the captions use ``system``.
    """
    from ..io.columns import label_system

    out_system, system = system, label_system(src, system)
    import numpy as np
    import pyarrow as pa

    from ..io import batch_labels

    batches = list(src.batches())
    table = pa.Table.from_batches(batches, schema=src.schema)
    values, reasons = [], []
    for b in batches:
        v, r = batch_labels(b, mode, radians)
        values.append(v)
        reasons.append(r)
    shape = (0, 3) if mode == "angles" else (0, 3, 3)
    values = np.concatenate(values) if values else np.zeros(shape)
    reasons = np.concatenate(reasons) if reasons else np.zeros(0, dtype=object)
    ok = reasons == ""
    A = np.full((len(values), 3, 3), np.nan)
    angles = np.full((len(values), 3), np.nan)
    if ok.any():
        if mode == "angles":
            A[ok] = system.to_canonical(system.from_angles(values[ok]))
            angles[ok] = values[ok]
        else:
            A[ok] = system.to_canonical(values[ok])
            angles[ok] = system.to_angles(values[ok])[0]
        if out_system is not system:
            angles[ok] = out_system.to_angles(out_system.from_canonical(A[ok]))[0]
    return table.to_pandas(), A, angles, reasons


def _column(frame, name):
    import numpy as np
    import pandas as pd

    if name not in frame.columns:
        return np.full(len(frame), np.nan)
    return pd.to_numeric(frame[name], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)


def face_placement(frame, pose_para: bool, length=None):
    """Per-row centre ``(N, 2)`` and length ``(N,)`` from the table, NaN where not given.

    Returns ``(centre, length, tdy_rows)``: ``tdy_rows`` marks rows whose centre
    came from ``tdx, tdy`` (so it may need flipping once the image height is known).
    """
    import numpy as np

    bx, by, bw, bh = (_column(frame, c) for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h"))
    has_box = np.isfinite(bx) & np.isfinite(by) & np.isfinite(bw) & np.isfinite(bh)
    tdx, tdy = _column(frame, "tdx"), _column(frame, "tdy")
    has_td = ~has_box & np.isfinite(tdx) & np.isfinite(tdy)
    centre = np.full((len(frame), 2), np.nan)
    centre[has_box] = np.stack([bx + bw / 2, by + bh / 2], axis=1)[has_box]
    centre[has_td] = np.stack([tdx, tdy], axis=1)[has_td]
    L = np.full(len(frame), np.nan)
    L[has_box] = (bh / 2)[has_box]
    size = _column(frame, "size")
    L = np.where(~has_box & np.isfinite(size), size, L)
    if pose_para:
        L = np.where(~has_box & ~np.isfinite(size), np.abs(_column(frame, "scale")) * MAT_LENGTH_UNITS, L)
    if length is not None:
        L = np.full(len(frame), float(length))
    L = np.where(np.isfinite(L) & (L > 0), L, np.nan)
    return centre, L, has_td


def _image_names(frame):
    """Image name per row (str), or None when the table names no images."""
    from pathlib import PurePath

    if "image" in frame.columns:
        return [None if v is None or v != v else str(v) for v in frame["image"].tolist()]
    if "file" in frame.columns:
        out = []
        for v in frame["file"].tolist():
            if v is None or v != v:
                out.append(None)
                continue
            p = PurePath(str(v))
            out.append(str(p.with_suffix(".jpg")) if p.suffix.lower() == ".mat" else str(p))
        return out
    return None


def _safe_relative(name, row):
    from pathlib import Path

    from ..errors import HpeError

    rel = Path(name)
    if rel.is_absolute():
        rel = Path(rel.name)
    if ".." in rel.parts or not rel.parts:
        raise HpeError(f"row {row}: image name {name!r} would be written outside the output folder")
    return rel


def run_draw(input_path, outdir, *, images=None, system, style="axes", canvas=None, radians=False, use="auto",
             length=None, thickness=None, tdy_origin="auto", annotate=False, grid=False, grid_cols=6, tile=256,
             limit=None, rejects_path=None, overwrite=False, progress=None) -> dict:
    """Draw every row of ``input_path``; return counts (``faces``, ``images``, ``sheets``, ``rejects``)."""
    from collections import Counter
    from pathlib import Path

    import numpy as np

    from ..errors import HpeError
    from ..geometry import draw as g
    from ..io import Rejects, label_mode, open_table
    from ..io.writers import AtomicFile

    input_path = Path(input_path)
    src = open_table(input_path)
    mode = label_mode(src.columns, src.path) if use == "auto" else use
    is_mat = input_path.is_dir() or input_path.suffix.lower() == ".mat"
    pose_para = is_mat or {"tdz", "scale"} <= set(src.columns)
    flip = tdy_origin == "bottom" or (tdy_origin == "auto" and pose_para)
    frame, A, angles, reasons = _read_all(src, mode, radians, system)
    n = len(frame)
    if n == 0:
        raise HpeError(f"{src.path}: empty table (no rows)")
    centre, L, from_td = face_placement(frame, pose_para, length)
    names = _image_names(frame)
    if names is None and canvas is None:
        raise HpeError(f"{src.path}: expected an `image` (or `file`) column naming the images, or --canvas WxH "
                       f"to draw on blank canvases; found {', '.join(frame.columns[:12])}")
    img_root = Path(images) if images else (input_path if input_path.is_dir() else input_path.parent)
    outdir = Path(outdir)
    rejects = Rejects(rejects_path, overwrite)

    # group rows by image, in order of first appearance
    import pandas as pd

    bad_rows = [(int(i), reasons[i]) for i in np.flatnonzero(reasons != "")]
    if names is None:
        name_arr = np.array([f"row_{i:06d}.png" for i in range(n)], dtype=object)
    else:
        name_arr = np.array(names, dtype=object)
        unnamed = np.flatnonzero((reasons == "") & pd.isna(name_arr))
        bad_rows += [(int(i), "no image name") for i in unnamed]
    usable = np.flatnonzero((reasons == "") & ~pd.isna(name_arr))
    codes, uniques = pd.factorize(name_arr[usable], sort=False)
    order = np.argsort(codes, kind="stable")
    cuts = np.flatnonzero(np.diff(codes[order])) + 1
    items = list(zip(uniques.tolist(), np.split(usable[order], cuts))) if usable.size else []
    if limit:
        items = items[:limit]

    # check every input and output before drawing anything
    plan = []
    for name, rows in items:
        rel = _safe_relative(name, rows[0])
        src_img = None
        if canvas is None:
            src_img = img_root / name
            if not src_img.is_file():
                bad_rows.extend((i, f"image not found: {src_img}") for i in rows)
                continue
        if canvas is not None and rel.suffix.lower() not in _WRITABLE:
            rel = rel.with_name(rel.name + ".png")
        dst = outdir / rel
        if src_img is not None and dst.resolve() == src_img.resolve():
            raise HpeError(f"{dst}: refusing to overwrite an input image (choose another output folder)")
        if not grid:
            check_output_exists(dst, overwrite)
        plan.append((name, rel, src_img, rows))
    if bad_rows:
        bad_rows.sort()
        if rejects.path is None:
            i, why = bad_rows[0]
            raise HpeError(f"{src.path}: row {i}: {why} ({len(bad_rows)} rows cannot be drawn; "
                           "use --rejects FILE to skip them)")
        idx = np.array([i for i, _ in bad_rows])
        cols = {"row": idx}
        cols.update({c: frame[c].to_numpy()[idx] for c in frame.columns})
        rejects.add(cols, [why for _, why in bad_rows])
    sheet_paths = []
    if grid:
        per_sheet = grid_cols * grid_cols
        n_sheets = max(1, -(-len(plan) // per_sheet))
        sheet_paths = [outdir / f"contact_sheet_{k + 1:03d}.png" for k in range(n_sheets)]
        for p in sheet_paths:
            check_output_exists(p, overwrite)
    outdir.mkdir(parents=True, exist_ok=True)
    if progress is not None:
        progress.total = len(plan)

    import cv2

    faces = drawn = 0
    tiles, captions = [], []
    for name, rel, src_img, rows in plan:
        if src_img is not None:
            img = cv2.imread(str(src_img), cv2.IMREAD_COLOR)
            if img is None:
                if rejects.path is None:
                    raise HpeError(f"{src_img}: not a readable image (row {rows[0]}; use --rejects FILE to skip it)")
                why = f"not a readable image: {src_img}"
                bad_rows.extend((int(i), why) for i in rows)
                rejects.add({"row": rows, **{c: frame[c].to_numpy()[rows] for c in frame.columns}}, [why] * len(rows))
                continue
        else:
            img = g.blank_canvas(*canvas)
        H, W = img.shape[:2]
        r = np.asarray(rows)
        c = centre[r].copy()
        flip_rows = from_td[r] & flip
        c[flip_rows, 1] = H - 1 - c[flip_rows, 1]
        missing = ~np.isfinite(c).all(axis=1)
        c[missing] = (W / 2.0, H / 2.0)
        Lr = np.where(np.isfinite(L[r]), L[r], DEFAULT_LENGTH_FRACTION * min(H, W))
        if style == "axes":
            g.render_axes(img, A[r], c, Lr, thickness)
        else:
            g.render_cube(img, A[r], c, Lr, thickness)
        if annotate:
            for k, i in enumerate(r):
                p, y, rr = angles[i]
                above = (1.15 if style == "axes" else 1.8) * Lr[k]
                ink = ((0, 0, 0), (255, 255, 255)) if src_img is None else ((255, 255, 255), (0, 0, 0))
                g.render_caption(img, f"p {p:.1f} y {y:.1f} r {rr:.1f}", (c[k, 0] - Lr[k], c[k, 1] - above),
                                 height_px=float(np.clip(Lr[k] / 6, 12.0, 0.05 * max(H, W) + 12.0)),
                                 colour=ink[0], outline=ink[1])
        faces += len(rows)
        drawn += 1
        if grid:
            s = tile / max(H, W)
            tiles.append(cv2.resize(img, (max(1, int(W * s)), max(1, int(H * s))), interpolation=cv2.INTER_AREA)
                         if s < 1 else img)
            captions.append(str(rel))
        else:
            _write_image(img, outdir / rel, overwrite, AtomicFile)
        if progress is not None:
            progress.update(1)
    if grid:
        per_sheet = grid_cols * grid_cols
        for k, p in enumerate(sheet_paths):
            part = slice(k * per_sheet, (k + 1) * per_sheet)
            if tiles[part]:
                sheet = g.contact_sheet(tiles[part], grid_cols, tile, captions[part])
                _write_image(sheet, p, overwrite, AtomicFile)
    rejects.write()
    return {"faces": faces, "images": drawn, "sheets": len(sheet_paths) if tiles else 0,
            "rejects": dict(Counter(why.split(":")[0] for _, why in bad_rows))}


def check_output_exists(path, overwrite):
    from ..errors import HpeError

    if path.exists() and not overwrite:
        raise HpeError(f"{path}: already exists (use --overwrite to replace it)")


def _write_image(img, path, overwrite, AtomicFile):
    import cv2

    from ..errors import HpeError

    path.parent.mkdir(parents=True, exist_ok=True)
    ext = path.suffix.lower() if path.suffix.lower() in _WRITABLE else ".png"
    ok, buf = cv2.imencode(ext, img)
    if not ok:
        raise HpeError(f"{path}: cannot encode the image as {ext}")
    with AtomicFile(path, overwrite) as tmp:
        tmp.write_bytes(buf.tobytes())
