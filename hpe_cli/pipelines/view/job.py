"""``hpe view`` as a job: a browsable offline page of every row of a label table (and a second one beside it).

Steps: read LABELS (and OTHER) once through the readers, each in its own system as every command resolves it
(:func:`hpe_cli.io.label_source.open_labels`); canonical matrices; angles in LABELS' system; join OTHER by key
with ``hpe evaluate``'s join (:mod:`.tables`); the geodesic angle between the two poses with
:func:`hpe_cli.metrics.rotation_errors.geodesic_deg` (what ``hpe evaluate`` reports per row); one thumbnail per
row and one reduced full frame per image (:mod:`.thumbs`: parallel, cached by content key); then the page
(:mod:`hpe_cli.report.view_page`). Everything is staged and committed with the run.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import HpeError
from ...geometry.draw import image_vectors
from ...io import Rejects
from ...io.images import ImageResolver, image_size, row_ids
from ...io.transaction import ensure_transaction, note_input, staged_dir
from ...metrics.rotation_errors import geodesic_deg
from ...report import view_page
from ...rotation.systems import get_system
from ..draw.rows import DEFAULT_LENGTH_FRACTION, face_placement, image_names
from ..pools import library_threads
from . import thumbs as vt
from .options import ViewOptions
from .tables import Table, pair, read_table


@dataclass
class Other:
    """OTHER joined to LABELS: one entry per row of LABELS (NaN / -1 where no row of OTHER pairs with it)."""

    A: np.ndarray  # (N, 3, 3) OTHER's canonical matrix
    angles: np.ndarray  # (N, 3) OTHER's pose in LABELS' system
    angle: np.ndarray  # (N,) geodesic angle between the two poses, degrees
    bidx: np.ndarray  # (N,) row of OTHER, -1 for none
    notes: list = field(default_factory=list)


@dataclass
class Pictures:
    """Where every row of LABELS is drawn: the distinct images (``refs``, ``sizes``, ``frame_names``), the image
    of each row (``img_code``, -1 for none), its placement and its thumbnail name (None when not shown),
    and why a usable row is not shown (``missing``, "" when it is)."""

    refs: list
    sizes: list
    img_code: np.ndarray
    missing: np.ndarray
    centre: np.ndarray
    length: np.ndarray
    crops: np.ndarray
    frame_names: list
    thumb: np.ndarray


def run_view(labels, outdir, other=None, options: ViewOptions = ViewOptions(), *, progress=None) -> dict:
    """Write a browsable page of every row of ``labels`` (and ``other`` beside it) into folder ``outdir``.

    Parameters
    ----------
    labels, other : str or Path
        Label tables (any reader: Parquet, CSV, text formats, ``.mat`` folders); ``other`` optional.
    outdir : str or Path
        Page folder; ``index.html`` opens from ``file://``. An earlier page there is the thumbnail cache.
    options : ViewOptions
        The command's settings (images, systems, ``also_in``, keys, threads, title, frames, rejects...).
    progress : tqdm, optional
        A bar whose total is set to the number of thumbnails made.

    Returns
    -------
    dict
        ``rows``, ``shown`` (rows with a thumbnail), ``whole_frame`` (rows without a head box, shown whole),
        ``made`` / ``reused`` (thumbnails made this run / kept from an earlier one), ``pruned`` (files of an
        earlier page in ``outdir`` this one no longer uses, removed with the commit), ``images``, ``matched``
        (rows of ``labels`` with a row of ``other``), ``keys``, ``rejects`` (reason -> count), ``system``,
        ``notes``.

    The pictures are made on ``options.threads`` threads, with OpenCV's and pyarrow's pools limited to as many
    (:func:`~hpe_cli.pipelines.pools.library_threads`); the page is the same bytes whatever the number.
    """
    with library_threads(options.threads) as threads:
        return _run_view(labels, outdir, other, options, threads, progress)


def _run_view(labels, outdir, other, options: ViewOptions, threads: int, progress) -> dict:
    outdir = Path(outdir)
    if (outdir / "index.html").exists() and not options.overwrite:
        raise HpeError(f"{outdir / 'index.html'}: exists (use --overwrite; thumbnails already made are reused)")
    a = read_table(labels, options.system, options.use, options.radians)
    if a.n == 0:
        raise HpeError(f"{a.src.path}: empty table (no rows)")
    b = None
    if other is not None:
        b = read_table(other, options.other_system or options.system, options.use, options.radians, "--other-system")
    rejects = Rejects(options.rejects, options.overwrite, strict=options.strict, source=a.src)
    counts: dict = {"rows": a.n}
    joined = _join(a, b, options.keys, rejects, counts)
    alt = also_angles(options.also_in, a.system, a.A, joined.A)
    root = Path(options.images) if options.images else (Path(labels) if Path(labels).is_dir() else Path(labels).parent)
    pics = _plan_pictures(a, root, joined.A, options.frames)
    ok = a.reasons == ""
    shown = ok & (pics.missing == "")
    counts["whole_frame"] = int((shown & (pics.crops[:, 0] == -1) & (pics.crops[:, 2] == -1)).sum())
    bad = np.flatnonzero(~ok | (pics.missing != ""))
    why = np.where(ok, pics.missing, a.reasons)
    _reject(rejects, a, bad, why[bad])
    if len(rejects) and (rejects.path is None or options.strict):
        rejects.check()  # fail before making any picture
    with ensure_transaction() as txn, staged_dir(outdir, options.overwrite) as stage:
        stage = Path(stage)
        failed, made = _make_pictures(a, pics, np.flatnonzero(shown), joined, (stage, outdir), threads, progress)
        for rows, reason in _failed_rows(pics, failed):  # unreadable after all: its rows become rejects
            _reject(rejects, a, rows, np.full(len(rows), reason, dtype=object))
            why[rows] = reason
        counts["made"] = made
        counts["shown"] = int(sum(t is not None for t in pics.thumb))
        counts["reused"] = counts["shown"] - counts["made"]
        counts["images"] = len(pics.refs)
        if counts["shown"] == 0:
            first = int(bad[0]) if len(bad) else 0
            raise HpeError(f"{a.where(first)}: nothing to show: every row was rejected (first: {why[first]})")
        title = options.title or Path(labels).name
        view_page.write_page(stage, _page(title, a, b, joined, alt, pics, why, counts))
        counts["pruned"] = _prune(txn, outdir, pics, failed, view_page.n_chunks(a.n))
        rejects.finish()
    counts["rejects"] = dict(rejects.counts)
    counts["system"] = a.resolved.describe()
    counts["notes"] = joined.notes
    return counts


def _join(a: Table, b: Table | None, keys, rejects, counts) -> Other:
    """OTHER's pose beside each row of LABELS (:func:`.tables.pair`), the angle between the two; OTHER's rows
    without a usable pose or without a row of LABELS go to ``rejects``. Sets ``counts["matched"]`` and
    ``counts["keys"]``."""
    out = Other(np.full_like(a.A, np.nan), np.full_like(a.angles, np.nan), np.full(a.n, np.nan),
                np.full(a.n, -1, dtype=np.int64))  # fmt: skip
    if b is None:
        return out
    ok = a.reasons == ""
    out.bidx, unmatched, keys, out.notes = pair(a, b, list(keys) if keys else None)
    bidx = out.bidx
    has = bidx >= 0
    has[has] &= b.reasons[bidx[has]] == ""
    out.A[has] = b.A[bidx[has]]
    both = has & ok
    if both.any():
        out.angle[both] = geodesic_deg(out.A[both], a.A[both])
        if b.system.name == a.system.name:  # the angles as OTHER wrote them
            out.angles[both] = b.angles[bidx[both]]
        else:  # OTHER's pose in LABELS' system, so the two read alike
            out.angles[both] = a.system.to_angles(a.system.from_canonical(out.A[both]))[0]
    bad_b = np.flatnonzero(b.reasons != "")
    if len(bad_b):  # OTHER's rows without a usable pose: kept in the page (no angle), listed as rejects
        _reject_other(rejects, b, bad_b, keys, b.reasons[bad_b].astype(object))
    counts["matched"] = int((bidx >= 0).sum())
    counts["keys"] = keys
    if len(unmatched):
        why = np.full(len(unmatched), f"no row of {a.src.path} with this key", dtype=object)
        _reject_other(rejects, b, unmatched, keys, why)
    return out


def _reject_other(rejects, b: Table, rows, keys, reasons) -> None:
    """Rows of OTHER into the rejects file: the table, the row and the key columns."""
    rejects.add(
        {"table": np.full(len(rows), str(b.src.path), dtype=object), "row": b.row_numbers()[rows],
         **{c: b.frame[c].to_numpy()[rows] for c in keys if c in b.frame}},
        reasons,
        where=b.where(int(rows[0])),
    )  # fmt: skip


def _plan_pictures(a: Table, root, A_other, frames: bool) -> Pictures:
    """Find each row's image, its size, the face's placement and crop, and name every picture by content."""
    ok = a.reasons == ""
    refs, img_code, missing = _resolve_images(a, root, ok)
    sizes, by_video = [], {}  # a video's frame size is asked once, not once per frame
    for r in refs:  # one per distinct picture
        if r.path is None and r.video not in by_video:
            by_video[r.video] = image_size(r)
        sizes.append(image_size(r) if r.path is not None else by_video[r.video])
    for k, s in enumerate(sizes):
        if s is None:
            missing[(img_code == k) & ok] = "not a readable image"
    centre, L, crops = _placement(a, sizes + [None], np.where(img_code >= 0, img_code, len(refs)))
    fp = vt.fingerprint_all(refs)
    frame_names = [None if not frames else
                   hashlib.blake2b(f"f{vt.VERSION}|{vt.FRAME_SIDE}|{f}".encode(), digest_size=10).hexdigest() + ".jpg"
                   for f in fp]  # fmt: skip
    thumb = np.full(a.n, None, dtype=object)
    idx = np.flatnonzero(ok & (missing == ""))
    if len(idx):
        keys_ = vt.picture_keys(np.array(fp, dtype=object)[img_code[idx]], crops[idx], centre[idx], L[idx],
                                a.A[idx], A_other[idx])  # fmt: skip
        thumb[idx] = keys_ + ".jpg"
    return Pictures(refs, sizes, img_code, missing, centre, L, crops, frame_names, thumb)


def _make_pictures(a: Table, pics: Pictures, idx, joined: Other, folders, threads: int, progress) -> tuple:
    """Make the pictures of rows ``idx`` that the earlier page in ``outdir`` does not have, into ``stage``
    (``folders = (stage, outdir)``). Returns ``(failed, made)``: ``[(ref, reason, thumbnails not made)]`` of the
    pictures that could not be read, and the number of thumbnails made."""
    stage, outdir = folders
    have_thumbs, have_frames = vt.existing(outdir, vt.THUMB_DIR), vt.existing(outdir, vt.FRAME_DIR)
    V = np.full((a.n, 3, 2), np.nan)
    V[idx] = image_vectors(a.A[idx])[:, :, :2]
    has_other = np.isfinite(joined.A).any()
    groups: dict = {}
    for i in idx:  # one entry per row to draw, grouped by image
        crop = None if pics.crops[i, 2] == -1 else tuple(pics.crops[i])
        other_i = joined.A[i] if has_other else None
        groups.setdefault(int(pics.img_code[i]), []).append(
            (pics.thumb[i], crop, pics.centre[i], float(pics.length[i]), V[i], other_i)
        )
    need_t = set(pics.thumb[idx].tolist()) - have_thumbs
    need_f = set(pics.frame_names) - have_frames - {None}
    vt.mkdirs(stage)
    items = [(pics.refs[k], pics.frame_names[k], rows) for k, rows in groups.items()]
    tasks = vt.make_tasks(items, stage, need_t, need_f)
    if progress is not None:
        progress.total = sum(t.n for t in tasks)
        progress.refresh()
    failed = vt.run_tasks(tasks, threads, progress)
    return failed, sum(t.n for t in tasks) - sum(n for _, _, n in failed)


def _failed_rows(pics: Pictures, failed):
    """Yield ``(rows, reason)`` for each picture that could not be read after all; their thumbnails are
    dropped."""
    ref_index = {r.key: k for k, r in enumerate(pics.refs)}
    for ref, reason, _ in failed:
        k = ref_index[ref.key]
        rows = np.flatnonzero((pics.img_code == k) & (pics.thumb != None))  # noqa: E711
        pics.thumb[rows] = None
        yield rows, reason


def _page(title, a: Table, b: Table | None, joined: Other, alt, pics: Pictures, why, counts):
    """What :func:`hpe_cli.report.view_page.write_page` writes."""
    status = np.where(pics.thumb != None, "ok", why)  # noqa: E711
    return view_page.Page(
        title=title,
        labels=a,
        other=b,
        bidx=joined.bidx,
        angles=a.angles,
        other_angles=joined.angles,
        also=alt,
        angle=joined.angle,
        A=a.A,
        A_other=joined.A,
        centre=pics.centre,
        length=pics.length,
        thumbs=pics.thumb,
        frames=list(pics.frame_names),
        sizes=pics.sizes,
        img_code=pics.img_code,
        status=status,
        counts=counts,
    )


def _placement(t: Table, sizes, img_code):
    """Per row: centre (N, 2), line length (N,), crop (N, 4) or -1, in image pixels."""
    centre, L, from_td = face_placement(t.frame, t.pose_para)
    W = np.array([s[0] if s else np.nan for s in sizes], dtype=np.float64)[img_code]
    H = np.array([s[1] if s else np.nan for s in sizes], dtype=np.float64)[img_code]
    if t.pose_para:  # Pose_Para tdy is measured from the bottom row
        centre[from_td, 1] = H[from_td] - 1 - centre[from_td, 1]
    none = ~np.isfinite(centre).all(axis=1)
    centre[none] = np.stack([W / 2, H / 2], axis=1)[none]
    L = np.where(np.isfinite(L), L, DEFAULT_LENGTH_FRACTION * np.minimum(W, H))
    boxes = np.stack(
        [t.frame[c].to_numpy(dtype=np.float64, na_value=np.nan) if c in t.frame else np.full(t.n, np.nan)
         for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h")], axis=1,
    )  # fmt: skip
    return centre, L, vt.crop_boxes(boxes)


def _resolve_images(t: Table, root, ok_rows):
    """``(refs of distinct images, code per row (-1: none), reasons per row for missing images)``."""
    n = t.n
    names = image_names(t.frame)
    reasons = np.full(n, "", dtype=object)
    code = np.full(n, -1, dtype=np.int64)
    if names is None:
        reasons[ok_rows] = "no image column (image or file)"
        return [], code, reasons
    names = np.array(names, dtype=object)
    seqs, cams, frs = row_ids(t.frame)
    key = (
        pd.Series(names).astype(str)
        + "\0"
        + pd.Series(seqs)
        + "\0"
        + pd.Series(cams)
        + "\0"
        + pd.Series(frs).astype(str)
    )
    codes, uniq = pd.factorize(key, sort=False)
    first = np.full(len(uniq), -1, dtype=np.int64)
    first[codes[::-1]] = np.arange(n)[::-1]
    resolver = ImageResolver(root)
    refs, ref_of, by_key = [], np.full(len(uniq), -1, dtype=np.int64), {}
    for u, i in enumerate(first):
        if pd.isna(names[i]):
            continue
        ref = resolver.find(names[i], seqs[i], cams[i], frs[i])
        if ref is None:
            continue
        if ref.key not in by_key:
            by_key[ref.key] = len(refs)
            refs.append(ref)
            note_input(ref.path or ref.video)
        ref_of[u] = by_key[ref.key]
    code = ref_of[codes]
    missing = code < 0
    nameless = pd.isna(names)
    reasons[missing & ok_rows & nameless] = "no image name"
    reasons[missing & ok_rows & ~nameless] = "image not found"
    return refs, code, reasons


def _prune(txn, outdir: Path, pics: Pictures, failed, chunks: int) -> int:
    """Remove, when the run commits, the files an earlier page in ``outdir`` left that this page no longer uses
    (thumbnails of rows dropped or changed, frames of images no longer shown, ``rows/`` files past the last
    chunk). Only names this command writes are considered; anything else in the folder is left alone."""
    bad = {r.key for r, _, _ in failed}
    keep = {
        vt.THUMB_DIR: {t for t in pics.thumb if t is not None},
        vt.FRAME_DIR: {f for f, r in zip(pics.frame_names, pics.refs) if f is not None and r.key not in bad},
        "rows": {f"{k:05d}.js" for k in range(chunks)},
    }
    pattern = {vt.THUMB_DIR: r"[0-9a-f]{20}\.jpg", vt.FRAME_DIR: r"[0-9a-f]{20}\.jpg", "rows": r"\d{5}\.js"}
    n = 0
    for sub, names in keep.items():
        for name in sorted(vt.existing(outdir, sub) - names):
            if re.fullmatch(pattern[sub], name):
                txn.remove_at_commit(outdir / sub / name)
                n += 1
    return n


def also_angles(systems, own, A, A_other) -> dict:
    """Per system of ``systems`` (not ``own``): ``(angles, other_angles)``, each (N, 3) pitch, yaw, roll in
    degrees (primary solution), NaN where the canonical matrix is unusable. Vectorised over all rows."""
    out: dict = {}
    for s in systems or []:
        s = get_system(s) if isinstance(s, str) else s
        if s.name == own.name or s.name in out:
            continue
        pair_ = []
        for M in (A, A_other):
            ang = np.full((len(M), 3), np.nan)
            ok = np.isfinite(M.reshape(len(M), 9)).all(axis=1)
            if ok.any():
                ang[ok] = s.to_angles(s.from_canonical(M[ok]))[0]
            pair_.append(ang)
        out[s.name] = tuple(pair_)
    return out


def _reject(rejects, t: Table, rows, reasons) -> None:
    if len(rows) == 0:
        return
    cols = {c: t.frame[c].to_numpy()[rows] for c in t.frame.columns if not c.startswith("lm")}
    rejects.add({"row": t.row_numbers()[rows], **cols}, np.asarray(reasons, dtype=object), lines=None)
