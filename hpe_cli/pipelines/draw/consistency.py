"""Pictures of the worst rows of ``hpe audit --consistency`` for the ``--plots`` page.

Each suspect among the worst is drawn on its image: the label's axes solid, the
axes of the rotation fitted to its landmarks dashed (same colours: red to the
subject's left, green forehead to chin, blue out of the nose), the landmarks the
fit used as white dots, a legend, and the angle between the two in the caption.
The axes start at the landmarks' centroid, with the length of the landmarks'
extent. Images are found by :class:`hpe_cli.io.images.ImageResolver`.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from ...geometry import draw as g
from ...io.images import ImageResolver, row_ids
from ...io.layout import landmark_count
from ...io.transaction import ensure_transaction, note_input, staged_dir
from ...report.consistency_page import page_html, score_figure
from .flagged import around_face, shrink_to_page
from .rows import image_names, write_image

#: sub-folder of the plots folder holding the page and its pictures
FOLDER = "consistency"


def _rows(batches, idx) -> tuple:
    """The rows ``idx`` (global indices, any order) of the re-read table as one pandas frame, in ``idx`` order."""
    want = np.asarray(idx, dtype=np.int64)
    got, at, offset = [], [], 0
    for batch in batches:
        n = batch.num_rows
        sel = np.flatnonzero((want >= offset) & (want < offset + n))
        if len(sel):
            got.append(batch.take(want[sel] - offset).to_pandas())
            at.append(sel)
        offset += n
    if not got:
        return pd.DataFrame(), np.zeros(0, np.int64)
    frame = pd.concat(got, ignore_index=True)
    order = np.argsort(np.concatenate(at), kind="stable")
    return frame.iloc[order].reset_index(drop=True), np.concatenate(at)[order]


def consistency_page(cons, report, batches, idx, plots_dir, images=None, overwrite=False) -> dict:
    """Write ``plots_dir/consistency/``: ``index.html``, ``scores.png`` and the rows ``idx`` drawn.

    ``idx``: global row indices of ``cons`` (the worst suspects). Returns
    ``{"pictures": [{"path", "caption"}], "missing": [(where, reason)]}`` (paths
    relative to ``plots_dir/consistency``).
    """
    with ensure_transaction(), staged_dir(Path(plots_dir) / FOLDER, overwrite) as stage:
        out = _pictures(cons, batches, idx, plots_dir, images, stage)
        score_figure(score_histograms(cons), stage / "scores.png")
        title = f"hpe audit --consistency: {cons.src.path.name}"
        (stage / "index.html").write_text(page_html(title, report, out), encoding="utf-8")
    return out


def score_histograms(cons, bins: int = 40) -> dict:
    """Histograms of ``landmark_angle``, ``view_angle`` and ``consistency_score`` over all rows, in flat memory.

    Each is binned over ``[max(min, 0), min(max, p99.5)]`` (values clipped to
    ``[0, p99.5]``; p99.5 from the audit's streamed quantiles) in one more pass
    over the audit's spill. Returns ``{column: {"counts", "edges", "median", "n"}}``
    (``None`` for a column without finite values).
    """
    sk = cons.sketches
    lims, counts = {}, {}
    for col, q in sk.items():
        if q.n:
            p = float(q.percentile(99.5)[0]) if q.n > 20 else q.max
            lo, hi = max(q.min, 0.0), min(q.max, p)
            lims[col] = (p, np.histogram_bin_edges(np.array([lo, hi]), bins=bins, range=(lo, hi)))
            counts[col] = np.zeros(bins, np.int64)
    if lims:
        for off, rec in cons.spill.chunks():
            sc = cons._score(rec, off)
            vals = {
                "landmark_angle": sc["lm_angle32"],
                "view_angle": sc["view_angle"].astype(np.float32),
                "consistency_score": sc["score"],
            }
            for col, (p, edges) in lims.items():
                v = np.asarray(vals[col], np.float64)
                v = v[np.isfinite(v)]
                counts[col] += np.histogram(np.clip(v, 0, p), bins=edges)[0]
    return {
        col: None
        if col not in lims
        else {"counts": counts[col], "edges": lims[col][1], "median": float(q.percentile(50)[0]), "n": int(q.n)}
        for col, q in sk.items()
    }


def _pictures(cons, batches, idx, plots_dir, images, stage) -> dict:
    out = {"pictures": [], "missing": []}
    frame, _ = _rows(batches, idx)
    if not len(frame):
        return out
    names = image_names(frame)
    if names is None:
        out["missing"] = [(f"row {cons.row(i)['line']}", "the table names no images") for i in idx]
        return out
    src = cons.src
    root = Path(images) if images else (src.path if src.path.is_dir() else src.path.parent)
    seqs, cams, frs = row_ids(frame)
    resolver = ImageResolver(root)
    n_lm = landmark_count(frame.columns)
    refs, jobs = [], []
    for k, i in enumerate(idx):
        line = cons.row(i)["line"]
        where = str(frame["file"].iat[k]) if "file" in frame.columns else src.where(line).split(": ", 1)[-1]
        ref = resolver.find(names[k], seqs[k], cams[k], frs[k]) if names[k] else None
        if ref is None:
            out["missing"].append((where, f"image not found: {resolver.tried(names[k], seqs[k])}"))
            continue
        note_input(ref.path or ref.video)
        if cons.mat_landmarks is not None:
            uv = cons.mat_landmarks[line - 1]
        elif n_lm:
            uv = np.stack(
                [frame[[f"lm{j}_x" for j in range(n_lm)]].iloc[k], frame[[f"lm{j}_y" for j in range(n_lm)]].iloc[k]], -1
            )
        else:
            uv = np.zeros((0, 2))
        refs.append(ref)
        jobs.append((int(i), where, np.asarray(uv, dtype=np.float64)))
    for j, img, why in ImageResolver.read(refs):
        i, where, uv = jobs[j]
        if img is None:
            out["missing"].append((where, why))
            continue
        r = cons.row(i)  # label and landmark fit from the audit's spill (half precision: for drawing)
        name = f"worst_{len(out['pictures']) + 1}.png"
        caption = f"{where}: score {r['score']:.1f}; {r['note']}"
        _draw(img, uv, r["A"], r["F"], r["landmark_angle"], stage / name, Path(plots_dir) / FOLDER / name)
        out["pictures"].append({"path": name, "caption": caption})
    return out


def _draw(img, uv, A, F, angle, staged, shown) -> None:
    H, W = img.shape[:2]
    ok = np.isfinite(uv).all(1) & ~((uv[:, 0] == -1) & (uv[:, 1] == -1)) if len(uv) else np.zeros(0, bool)
    pts = uv[ok]
    if len(pts):
        c = pts.mean(0)
        length = 0.6 * float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]), 10.0))
    else:
        c, length = np.array([W / 2.0, H / 2.0]), 0.25 * min(H, W)
    r = max(2, int(round(length / 40)))
    for p in pts:
        cv2.circle(img, (int(round(p[0])), int(round(p[1]))), r, (255, 255, 255), -1, cv2.LINE_AA)
    if A is not None:
        g.render_axes(img, np.asarray(A, np.float64)[None], c[None], np.array([length]))
    if F is not None and np.isfinite(F).all():
        g.render_axes_dashed(img, np.asarray(F, np.float64)[None], c[None], np.array([length]))
    img = shrink_to_page(around_face(img, c, length))
    h = max(12.0, 0.04 * min(img.shape[:2]))
    g.render_legend(img, [("label", "solid"), ("landmark fit", "dashed")], height_px=h)
    if np.isfinite(angle):
        g.render_caption(img, f"{angle:.1f} deg apart", (4, img.shape[0] - 6), height_px=h)
    write_image(img, staged, shown)


__all__ = ["FOLDER", "consistency_page"]
