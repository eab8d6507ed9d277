"""Pictures of flagged rows for ``hpe audit --plots``: the first few rows of each check, drawn on their images.

The rows are the audit's examples (their line numbers); the audit's own :class:`~hpe_cli.io.label_source.LabelSource`
is read once more (same stream, same system, same label columns), keeping only those rows.
Each is drawn as ``hpe draw`` draws it (:mod:`hpe_cli.pipelines.draw`: the label's axes from the head centre -
box, ``tdx, tdy`` or Pose_Para - red to the subject's left, green forehead to chin, blue out of the nose) with
the check's name in the top-left corner, shrunk to at most :data:`MAX_SIDE` pixels and written as
``pictures/<check>_<k>.png`` in the plots folder. Images are found by :class:`hpe_cli.io.images.ImageResolver`
(``--images``, a ``.mat`` folder's own ``.jpg``, Panoptic frame layouts and videos).
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ...geometry import draw as g
from ...io.images import IMAGE_COLUMNS, ImageResolver, row_ids
from ...io.readers import LINE_COL
from ...io.transaction import ensure_transaction, note_input, staged_dir
from .rows import DEFAULT_LENGTH_FRACTION, face_placement, image_names, read_rows, write_image

#: pictures per check
PER_CHECK = 3
#: longest side of a picture on the page, pixels
MAX_SIDE = 480
#: sub-folder of the plots folder holding the pictures
PICTURE_DIR = "pictures"


def _wanted(examples, per_check):
    """``{check: [line, ...]}`` of the first ``per_check`` example rows of each check."""
    out = {}
    for check, rows in (examples or {}).items():
        lines = [int(e["row"]) for e in rows if isinstance(e, dict) and "row" in e][:per_check]
        if lines:
            out[check] = lines
    return out


def _pick(src, lines):
    """The batches of ``src`` cut down to the rows whose line is in ``lines``."""
    want = pa.array(sorted(lines), type=pa.int64())
    for batch, _ in src.batches_with_rejects():
        keep = pc.is_in(batch.column(LINE_COL).cast(pa.int64()), value_set=want)
        if pc.any(keep).as_py():
            yield batch.filter(keep)


def flagged_pictures(labels, examples, plots_dir, *, images=None, per_check=PER_CHECK, radians=False, overwrite=False):
    """Draw the first ``per_check`` flagged rows of each check; return what the page shows.

    Parameters
    ----------
    labels : LabelSource
        The audited table as the audit opened it (:func:`hpe_cli.io.label_source.open_labels`, with line
        numbers): its rows are read again in ``labels.system`` with ``labels.mode``; the file is not opened or
        its system resolved a second time.
    examples : dict
        ``{check: [{"row": line, ...}, ...]}``, the audit report's examples (``row`` = the reader's line number:
        the CSV line, header = 1; the 1-based row otherwise).
    plots_dir : str or Path
        The ``--plots`` folder; pictures go to its ``pictures/`` sub-folder, staged with the run.
    images : str or Path, optional
        Image root (default: the table's folder; a ``.mat`` folder itself).
    per_check : int
        Pictures per check.
    radians : bool
        Angle columns in radians.
    overwrite : bool
        Replace pictures of an earlier run.

    Returns
    -------
    dict
        ``pictures``: list of ``{"check", "where", "path" (relative to plots_dir), "caption"}`` in check order;
        ``missing``: rows whose image was not found or not readable, ``[(check, where, reason)]``;
        ``root``: the image root.
    """
    src = labels.table
    input_path = Path(src.path)
    root = Path(images) if images else (input_path if input_path.is_dir() else input_path.parent)
    result = {"pictures": [], "missing": [], "root": str(root)}
    wanted = _wanted(examples, per_check)
    if not wanted or not src.with_lines:  # no examples, or no line numbers to find them by
        return result
    if not any(c in src.columns for c in IMAGE_COLUMNS):  # no image names: no pictures (and no second read)
        return result
    rows = read_rows(labels, radians, batches=_pick(src, {n for v in wanted.values() for n in v}))
    names = image_names(rows.frame)
    if names is None or not len(rows.frame):
        return result
    jobs, refs = _find(src, rows, names, wanted, root, result)
    if not jobs:
        return result
    frame = rows.frame
    pose_para = input_path.is_dir() or input_path.suffix.lower() == ".mat" or {"tdz", "scale"} <= set(frame.columns)
    out_dir = Path(plots_dir) / PICTURE_DIR
    drawn = {}
    with ensure_transaction(), staged_dir(out_dir, overwrite) as stage:
        for j, img, why in ImageResolver.read(refs):
            check, k, i, where = jobs[j]
            if img is None:
                result["missing"].append((check, where, why))
                continue
            rel = Path(f"{_safe(check)}_{k + 1}.png")
            ok = rows.reasons[i] == "" and np.isfinite(rows.A[i]).all()
            _draw_one(img, frame, i, rows.A[i] if ok else None, pose_para, check, stage / rel, out_dir / rel)
            label = "" if ok else f" (label not drawn: {rows.reasons[i] or 'not finite'})"
            shown = "" if input_path.is_dir() else f" ({names[i]})"
            drawn[j] = {
                "check": check,
                "where": where,
                "path": f"{PICTURE_DIR}/{rel.name}",
                "caption": f"{check}: {where}{shown}{label}",
            }
    result["pictures"] = [drawn[j] for j in sorted(drawn)]
    return result


def _find(src, rows, names, wanted, root, result):
    """``(jobs, refs)``: ``(check, k, row, where)`` and the image of each wanted row that has one; the others
    go to ``result["missing"]``."""
    at = {int(n): i for i, n in enumerate(rows.lines)}
    seqs, cams, frs = row_ids(rows.frame)
    resolver = ImageResolver(root)
    jobs, refs = [], []
    for check, ls in wanted.items():
        for k, line in enumerate(n for n in ls if n in at):
            i = at[line]
            where = _where(src, rows.frame, i, line)
            ref = resolver.find(names[i], seqs[i], cams[i], frs[i]) if names[i] else None
            if ref is None:
                result["missing"].append((check, where, f"image not found: {resolver.tried(names[i], seqs[i])}"))
                continue
            note_input(ref.path or ref.video)
            jobs.append((check, k, i, where))
            refs.append(ref)
    return jobs, refs


def _where(src, frame, i, line) -> str:
    """A row as messages name it: the ``.mat`` file, ``line N`` of a text file, else ``row N`` (1-based)."""
    if Path(src.path).is_dir() and "file" in frame.columns:
        return str(frame["file"].iat[i])
    return src.where(line).split(": ", 1)[-1]  # the reader's __line__ is already that number


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text)[:60] or "check"


def around_face(img, centre, length):
    """The part of ``img`` around the face: a square of side ``6 * length`` (at least 160 px) about ``centre``,
    cut to the image; a small face in a large frame stays visible on the page."""
    H, W = img.shape[:2]
    half = max(3.0 * float(length), 80.0)
    x0, x1 = int(max(0, np.floor(centre[0] - half))), int(min(W, np.ceil(centre[0] + half)))
    y0, y1 = int(max(0, np.floor(centre[1] - half))), int(min(H, np.ceil(centre[1] + half)))
    if x1 - x0 < 16 or y1 - y0 < 16:  # the centre is outside the image: show all of it
        return img
    return np.ascontiguousarray(img[y0:y1, x0:x1])


def shrink_to_page(img):
    """``img`` shrunk (area averaging) so that its longer side is at most :data:`MAX_SIDE` pixels."""
    H, W = img.shape[:2]
    s = MAX_SIDE / max(H, W)
    if s < 1:
        img = cv2.resize(img, (max(1, round(W * s)), max(1, round(H * s))), interpolation=cv2.INTER_AREA)
    return img


def _draw_one(img, frame, i, A, pose_para, check, staged, shown):
    """The row's axes (as ``hpe draw`` places them) and the check's name; shrunk; staged as PNG."""
    H, W = img.shape[:2]
    if A is not None:
        c, L, from_td = face_placement(frame.iloc[[i]], pose_para)
        c = c[0].copy()
        if from_td[0] and pose_para:
            c[1] = H - 1 - c[1]
        if not np.isfinite(c).all():
            c = np.array([W / 2.0, H / 2.0])
        length = L[0] if np.isfinite(L[0]) else DEFAULT_LENGTH_FRACTION * min(H, W)
        g.render_axes(img, A[None], c[None], np.array([length]))
        img = around_face(img, c, length)
    img = shrink_to_page(img)
    h = max(14.0, 0.045 * min(img.shape[:2]))
    g.render_caption(img, check, (4, 4 + h), height_px=h)
    write_image(img, staged, shown)


__all__ = ["MAX_SIDE", "PER_CHECK", "PICTURE_DIR", "around_face", "flagged_pictures", "shrink_to_page"]
