"""``hpe draw`` as a job: read labels, draw each image once with all its rows, write them with the run.

The images (or contact sheets) are written into a staged folder
(:func:`hpe_cli.io.transaction.staged_dir`) and moved into the output folder
when the run commits: a failure leaves no image behind, and a rerun never
meets images of a failed run.
"""

from __future__ import annotations

from pathlib import Path

from .draw_rows import (  # noqa: F401  (shared with draw_errors and draw_flagged)
    _WRITABLE,
    DEFAULT_LENGTH_FRACTION,
    MAT_LENGTH_UNITS,
    _column,
    _image_names,
    _read_all,
    _read_image,
    _read_stored,
    _safe_relative,
    _write_image,
    face_placement,
    row_namer,
    row_numbers,
)


def _group_rows(names, usable, limit):
    """``[(name, rows)]`` in order of first appearance."""
    import numpy as np
    import pandas as pd

    codes, uniques = pd.factorize(names[usable], sort=False)
    order = np.argsort(codes, kind="stable")
    cuts = np.flatnonzero(np.diff(codes[order])) + 1
    items = list(zip(uniques.tolist(), np.split(usable[order], cuts))) if usable.size else []
    return items[:limit] if limit else items


def plan_images(items, *, img_root, outdir, canvas, frame, where, overwrite, check_exists=True):
    """Resolve each image and its output name; ``(plan, bad_rows)``.

    ``plan`` is a list of ``[name, rel, ref, rows]`` (``ref`` an :class:`hpe_cli.io.images.ImageRef` or None on
    canvases). Rows naming the same picture (even by different names, e.g. ``a.mat`` and ``a.jpg``) are drawn
    together on it; two different pictures that would be written to the same output name are an error naming
    a row of each.
    """
    import numpy as np

    from ..errors import HpeError
    from ..io.images import ImageResolver, row_ids
    from ..io.transaction import note_input

    resolver = ImageResolver(img_root)
    seqs, cams, frs = row_ids(frame)
    plan, bad_rows, by_rel = [], [], {}
    for name, rows in items:
        i0 = int(rows[0])
        rel = _safe_relative(name, where(i0))
        ref = None
        if canvas is None:
            ref = resolver.find(name, seqs[i0], cams[i0], frs[i0])
            if ref is None:
                bad_rows.extend((int(i), f"image not found: {resolver.tried(name, seqs[i0])}") for i in rows)
                continue
            note_input(ref.path or ref.video)  # an image read is an input: no output may replace it
        elif rel.suffix.lower() not in _WRITABLE:
            rel = rel.with_name(rel.name + ".png")
        key = str(rel)
        if key in by_rel:
            other = by_rel[key]
            if ref is not None and other[2] is not None and other[2].key == ref.key:
                other[3] = np.sort(np.concatenate([other[3], rows]))
                continue
            raise HpeError(
                f"{where(i0)}: image {name!r} would be written to {outdir / rel}, as "
                f"{other[0]!r} of {where(int(other[3][0])).split(': ', 1)[-1]} is: two different "
                "pictures for one output file (give the images distinct names)"
            )
        dst = outdir / rel
        if ref is not None and ref.path is not None and dst.resolve() == Path(ref.path).resolve():
            raise HpeError(f"{dst}: refusing to overwrite an input image (choose another output folder)")
        if check_exists:
            check_output_exists(dst, overwrite)
        entry = [name, rel, ref, np.asarray(rows)]
        by_rel[key] = entry
        plan.append(entry)
    return plan, bad_rows


def run_draw(
    input_path,
    outdir,
    *,
    images=None,
    system,
    style="axes",
    canvas=None,
    radians=False,
    use="auto",
    length=None,
    thickness=None,
    tdy_origin="auto",
    annotate=False,
    grid=False,
    grid_cols=6,
    tile=256,
    limit=None,
    rejects_path=None,
    overwrite=False,
    progress=None,
    strict=False,
    worst=None,
    sort_by=None,
) -> dict:
    """Draw every row of ``input_path``; return counts (``faces``, ``images``, ``sheets``, ``rejects``).

    A table written by ``hpe evaluate -o`` (``gt_*`` and ``pred_*`` columns) is drawn by
    :func:`hpe_cli.pipelines.draw_errors.run_draw_errors` instead.
    """
    import numpy as np
    import pandas as pd

    from ..errors import HpeError
    from ..io import Rejects, label_mode, open_table
    from ..io.transaction import ensure_transaction, staged_dir

    input_path = Path(input_path)
    src = open_table(input_path, with_lines=True)
    from .draw_errors import is_errors_table, run_draw_errors

    if is_errors_table(src.columns):
        return run_draw_errors(
            input_path,
            outdir,
            images=images,
            system=system,
            worst=worst,
            sort_by=sort_by or "geodesic",
            overwrite=overwrite,
            progress=progress,
            thickness=thickness,
            rejects_path=rejects_path,
            strict=strict,
        )
    if worst is not None or sort_by is not None:
        raise HpeError(
            f"{src.path}: --worst and --sort-by draw the output of `hpe evaluate -o` (columns "
            "gt_pitch..pred_roll), got a label table"
        )
    from ..io.system_meta import output_system, resolve_system

    resolved = resolve_system(src, system, option_is_output=True)  # the file's own system, else --system
    system = output_system(resolved)
    mode = label_mode(src.columns, src.path, system) if use == "auto" else use
    is_mat = input_path.is_dir() or input_path.suffix.lower() == ".mat"
    pose_para = is_mat or {"tdz", "scale"} <= set(src.columns)
    flip = tdy_origin == "bottom" or (tdy_origin == "auto" and pose_para)
    read_rejects: list = []  # rows the reader cannot parse: with --rejects they are rejects, not the run's end
    batches = None
    if rejects_path is not None:
        batches = []
        for b, rr in src.batches_with_rejects():
            batches.append(b)
            read_rejects += rr
    frame, A, angles, reasons, lines = _read_all(src, mode, radians, system, batches=batches)
    where = row_namer(src, lines)
    n = len(frame)
    rejects = Rejects(rejects_path, overwrite, strict=strict, source=src.path)
    rejects.add_unreadable(read_rejects)
    if n == 0 and read_rejects:
        from ..io.rejects import fail_all_rejected

        rejects.check()  # --strict: nothing written
        fail_all_rejected(
            rejects,
            f"{src.path}: nothing drawn: all {len(read_rejects)} row(s) rejected "
            f"(first: line {read_rejects[0].line}: {read_rejects[0].reason})",
        )
    if n == 0:
        raise HpeError(f"{src.path}: empty table (no rows)")
    centre, L, from_td = face_placement(frame, pose_para, length)
    names = _image_names(frame)
    if names is None and canvas is None:
        raise HpeError(
            f"{src.path}: expected an `image` (or `file`) column naming the images, or --image-size WxH "
            f"to draw on blank canvases; found {', '.join(frame.columns[:12])}"
        )
    img_root = Path(images) if images else (input_path if input_path.is_dir() else input_path.parent)
    outdir = Path(outdir)

    bad_rows = [(int(i), reasons[i]) for i in np.flatnonzero(reasons != "")]
    if names is None:
        name_arr = np.array([f"row_{i:06d}.png" for i in range(n)], dtype=object)
    else:
        name_arr = np.array(names, dtype=object)
        unnamed = np.flatnonzero((reasons == "") & pd.isna(name_arr))
        bad_rows += [(int(i), "no image name") for i in unnamed]
    usable = np.flatnonzero((reasons == "") & ~pd.isna(name_arr))
    items = _group_rows(name_arr, usable, limit)

    # check every input and output before drawing anything
    plan, missing = plan_images(
        items,
        img_root=img_root,
        outdir=outdir,
        canvas=canvas,
        frame=frame,
        where=where,
        overwrite=overwrite,
        check_exists=not grid,
    )
    bad_rows += missing
    book = _Book(rejects, frame, src, lines, where)
    book.add(bad_rows, before_drawing=True)
    sheet_paths = []
    if grid:
        per_sheet = grid_cols * grid_cols
        n_sheets = max(1, -(-len(plan) // per_sheet))
        sheet_paths = [outdir / f"contact_sheet_{k + 1:03d}.png" for k in range(n_sheets)]
        for p in sheet_paths:
            check_output_exists(p, overwrite)
    if progress is not None:
        progress.total = len(plan)
        progress.refresh()
    with ensure_transaction(), staged_dir(outdir, overwrite) as stage:
        s = _draw_all(
            plan,
            stage,
            outdir,
            grid,
            grid_cols,
            tile,
            sheet_paths,
            canvas,
            centre,
            L,
            from_td,
            flip,
            style,
            thickness,
            annotate,
            A,
            angles,
            book,
            progress,
        )
        book.finish(s["images"])
        if read_rejects:  # unparseable rows, set aside before drawing, count in the summary too
            from collections import Counter

            read = Counter(r.reason.split(":")[0] for r in read_rejects)
            s["rejects"] = dict(read + Counter(s["rejects"]))
        s["system"] = resolved.describe()  # which system the labels were read in, and where that came from
        return s


class _Book:
    """Rejected rows of a draw run: numbered as the input numbers them, checked before anything is drawn."""

    def __init__(self, rejects, frame, src, lines, where):
        self.rejects, self.frame, self.src, self.lines, self.where = rejects, frame, src, lines, where
        self.rows: list = []

    def add(self, bad, before_drawing=False):
        import numpy as np

        if not bad:
            return
        bad = sorted(bad)
        self.rows += bad
        idx = np.array([i for i, _ in bad])
        why = [w for _, w in bad]
        if self.rejects.path is None or self.rejects.strict:  # fail before drawing anything
            from ..errors import HpeError

            extra = (
                f" ({len(bad) - 1} more; use --rejects FILE to skip them)"
                if len(bad) > 1
                else " (use --rejects FILE to skip it)"
            )
            raise HpeError(f"{self.where(idx[0])}: {why[0]}{extra if not self.rejects.strict else ''}")
        cols = {c: self.frame[c].to_numpy()[idx] for c in self.frame.columns}
        if Path(self.src.path).is_dir() and "file" in cols:  # a .mat file is one record: named as messages do
            cols["file"] = np.array([self.where(i) for i in idx], dtype=object)
        else:
            cols = {"row": row_numbers(self.src, self.lines, idx), **cols}
        self.rejects.add(cols, why)

    def finish(self, drawn):

        if drawn == 0 and self.rows:  # the rejects file is still written: it says why
            from ..io.rejects import fail_all_rejected

            fail_all_rejected(
                self.rejects,
                f"{self.src.path}: nothing drawn: all {len(self.rows)} row(s) rejected "
                f"(first: {self.where(self.rows[0][0]).split(': ', 1)[-1]}: {self.rows[0][1]})",
            )
        self.rejects.finish()


def pictures(plan, canvas):
    """Yield ``(plan entry, BGR image or None, reason)``; video frames are decoded once per video, in order."""
    from ..geometry import draw as g
    from ..io.images import ImageResolver

    if canvas is not None:
        for entry in plan:
            yield entry, g.blank_canvas(*canvas), ""
        return
    for k, img, why in ImageResolver.read([e[2] for e in plan]):
        yield plan[k], img, why


def _draw_all(
    plan,
    stage,
    outdir,
    grid,
    grid_cols,
    tile,
    sheet_paths,
    canvas,
    centre,
    L,
    from_td,
    flip,
    style,
    thickness,
    annotate,
    A,
    angles,
    book,
    progress=None,
):
    from collections import Counter

    import cv2
    import numpy as np

    from ..geometry import draw as g

    faces = drawn = 0
    tiles, captions = [], []
    for (name, rel, ref, rows), img, why in pictures(plan, canvas):
        if img is None:
            book.add([(int(i), why) for i in rows])
            continue
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
                ink = ((0, 0, 0), (255, 255, 255)) if ref is None else ((255, 255, 255), (0, 0, 0))
                g.render_caption(
                    img,
                    f"p {p:.1f} y {y:.1f} r {rr:.1f}",
                    (c[k, 0] - Lr[k], c[k, 1] - above),
                    height_px=float(np.clip(Lr[k] / 6, 12.0, 0.05 * max(H, W) + 12.0)),
                    colour=ink[0],
                    outline=ink[1],
                )
        faces += len(rows)
        drawn += 1
        if grid:
            s = tile / max(H, W)
            tiles.append(
                cv2.resize(img, (max(1, int(W * s)), max(1, int(H * s))), interpolation=cv2.INTER_AREA)
                if s < 1
                else img
            )
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
    return {
        "faces": faces,
        "images": drawn,
        "sheets": len(sheet_paths) if tiles else 0,
        "rejects": dict(Counter(why.split(":")[0] for _, why in book.rows)),
    }


def check_output_exists(path, overwrite):
    from ..errors import HpeError

    if path.exists() and not overwrite:
        raise HpeError(f"{path}: already exists (use --overwrite to replace it)")


def draw_worst(rows, *, images, out_dir, worst=None, sort_by="geodesic", **kw):
    """See :func:`hpe_cli.pipelines.draw_errors.draw_worst` (re-exported here)."""
    from .draw_errors import draw_worst as _dw

    return _dw(rows, images=images, out_dir=out_dir, worst=worst, sort_by=sort_by, **kw)
