"""``hpe draw`` as a job: read labels, draw each image once with all its rows, write them with the run.

The images (or contact sheets) are written into a staged folder
(:func:`hpe_cli.io.transaction.staged_dir`) and moved into the output folder
when the run commits: a failure leaves no image behind, and a rerun never
meets images of a failed run.
"""
from __future__ import annotations

#: 300W-LP/AFLW2000 Pose_Para: line length = this many Basel-Face-Model units times ``scale``.
#: The model is in micrometres and its origin is the centre of the head (the nose tip is
#: about 130 mm in front of it, the outer eye corners 43 mm to each side).
MAT_LENGTH_UNITS = 100_000.0
#: when a row gives no size: line length as a fraction of min(image width, height)
DEFAULT_LENGTH_FRACTION = 0.25
_WRITABLE = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"}


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
    if mode not in ("angles", "matrix") or (system.columns and all(c in src.columns for c in system.value_columns)):
        A, angles, reasons = _read_stored(batches, mode, radians, system)
        ok = reasons == ""
        if out_system is not system and ok.any():
            angles[ok] = out_system.to_angles(out_system.from_canonical(A[ok]))[0]
        return table.to_pandas(), A, angles, reasons
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


def _read_stored(batches, mode, radians, system):
    """(canonical A, angles, reasons) of any storage kind (rotation vectors, quaternions, 6-D, named columns)."""
    import numpy as np

    from ..io import batch_rotations
    from ..rotation import soa

    As, angles, reasons = [], [], []
    for b in batches:
        X, ok, r = batch_rotations(b, system, mode, radians)
        R = soa.to_array(X, b.num_rows)
        a = np.full((b.num_rows, 3, 3), np.nan)
        g = np.full((b.num_rows, 3), np.nan)
        if ok.any():
            a[ok] = system.to_canonical(R[ok])
            g[ok] = system.to_angles(R[ok])[0]
        As.append(a)
        angles.append(g)
        reasons.append(r if r is not None else np.full(b.num_rows, "", dtype=object))
    if not As:
        return np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0, dtype=object)
    return np.concatenate(As), np.concatenate(angles), np.concatenate(reasons)


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
        raise HpeError(f"{row}: image name {name!r} would be written outside the output folder")
    return rel


def run_draw(input_path, outdir, *, images=None, system, style="axes", canvas=None, radians=False, use="auto",
             length=None, thickness=None, tdy_origin="auto", annotate=False, grid=False, grid_cols=6, tile=256,
             limit=None, rejects_path=None, overwrite=False, progress=None, strict=False) -> dict:
    """Draw every row of ``input_path``; return counts (``faces``, ``images``, ``sheets``, ``rejects``)."""
    from pathlib import Path

    import numpy as np

    from ..errors import HpeError
    from ..io import Rejects, label_mode, open_table
    from ..io.transaction import ensure_transaction, note_input, staged_dir

    input_path = Path(input_path)
    src = open_table(input_path, with_lines=True)
    from ..io.system_meta import output_system, resolve_system

    system = output_system(resolve_system(src, system, option_is_output=True))  # file's own, else --system
    mode = label_mode(src.columns, src.path, system) if use == "auto" else use
    is_mat = input_path.is_dir() or input_path.suffix.lower() == ".mat"
    pose_para = is_mat or {"tdz", "scale"} <= set(src.columns)
    flip = tdy_origin == "bottom" or (tdy_origin == "auto" and pose_para)
    frame, A, angles, reasons = _read_all(src, mode, radians, system)
    line_no = frame.pop("__line__").to_numpy()  # each row's number in messages and rejects (src.where)
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
    rejects = Rejects(rejects_path, overwrite, strict=strict, source=src)

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
        rel = _safe_relative(name, src.where(line_no[rows[0]]))
        src_img = None
        if canvas is None:
            src_img = img_root / name
            if not src_img.is_file():
                bad_rows.extend((i, f"image not found: {src_img}") for i in rows)
                continue
            note_input(src_img)  # an image read is an input: no output may replace it
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
        if rejects.path is None or strict:  # fail before drawing anything
            rejects.add({"row": line_no[np.array([i for i, _ in bad_rows])]}, [why for _, why in bad_rows])
            rejects.check()
        idx = np.array([i for i, _ in bad_rows])
        cols = {"row": line_no[idx]}
        cols.update({c: frame[c].to_numpy()[idx] for c in frame.columns})
        rejects.add(cols, [why for _, why in bad_rows])
    sheet_paths = []
    if grid:
        per_sheet = grid_cols * grid_cols
        n_sheets = max(1, -(-len(plan) // per_sheet))
        sheet_paths = [outdir / f"contact_sheet_{k + 1:03d}.png" for k in range(n_sheets)]
        for p in sheet_paths:
            check_output_exists(p, overwrite)
    if progress is not None:
        progress.total = len(plan)
    with ensure_transaction(), staged_dir(outdir, overwrite) as stage:
        return _draw_all(plan, stage, outdir, grid, grid_cols, tile, sheet_paths, canvas, centre, L, from_td, flip,
                         style, thickness, annotate, A, angles, frame, rejects, bad_rows, progress, line_no, src)


def _draw_all(plan, stage, outdir, grid, grid_cols, tile, sheet_paths, canvas, centre, L, from_td, flip, style,
              thickness, annotate, A, angles, frame, rejects, bad_rows, progress=None, line_no=None, src=None):
    from collections import Counter

    import cv2
    import numpy as np

    from ..errors import HpeError
    from ..geometry import draw as g

    faces = drawn = 0
    tiles, captions = [], []
    for name, rel, src_img, rows in plan:
        if src_img is not None:
            img = _read_image(src_img)
            if img is None:
                if rejects.path is None or rejects.strict:
                    raise HpeError(f"{src_img}: not a readable image ({src.where(line_no[rows[0]])}; use --rejects "
                                   "FILE to skip it)")
                why = f"not a readable image: {src_img}"
                bad_rows.extend((int(i), why) for i in rows)
                rejects.add({"row": line_no[rows], **{c: frame[c].to_numpy()[rows] for c in frame.columns}},
                            [why] * len(rows))
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
            _write_image(img, stage / rel, outdir / rel)
        if progress is not None:
            progress.update(1)
    if grid:
        per_sheet = grid_cols * grid_cols
        for k, p in enumerate(sheet_paths):
            part = slice(k * per_sheet, (k + 1) * per_sheet)
            if tiles[part]:
                sheet = g.contact_sheet(tiles[part], grid_cols, tile, captions[part])
                _write_image(sheet, stage / p.relative_to(outdir), p)
    rejects.finish()
    return {"faces": faces, "images": drawn, "sheets": len(sheet_paths) if tiles else 0,
            "rejects": dict(Counter(why.split(":")[0] for _, why in bad_rows))}


def check_output_exists(path, overwrite):
    from ..errors import HpeError

    if path.exists() and not overwrite:
        raise HpeError(f"{path}: already exists (use --overwrite to replace it)")


def _read_image(path):
    """BGR image or None; read as bytes first (OpenCV's own file functions cannot take non-UTF-8 names)."""
    import cv2
    import numpy as np

    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError:
        return None
    return cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None


def _write_image(img, staged, shown):
    """Encode ``img`` by ``shown``'s extension (PNG if unknown) into ``staged`` (a file in the staged folder)."""
    import cv2

    from ..errors import HpeError
    from ..io.transaction import os_reason

    staged.parent.mkdir(parents=True, exist_ok=True)
    ext = shown.suffix.lower() if shown.suffix.lower() in _WRITABLE else ".png"
    ok, buf = cv2.imencode(ext, img)
    if not ok:
        raise HpeError(f"{shown}: cannot encode the image as {ext}")
    try:
        staged.write_bytes(buf.tobytes())
    except OSError as exc:
        raise HpeError(f"{shown}: cannot write: {os_reason(exc)}") from None
