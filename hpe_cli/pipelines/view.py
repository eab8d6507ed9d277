"""``hpe view`` as a job: a browsable offline page of every row of a label table (and a second one beside it).

Steps: read LABELS (and OTHER) once through the readers, each in its own system as every command resolves it
(:func:`hpe_cli.io.system_meta.resolve_system`); canonical matrices; angles in LABELS' system; join OTHER by key
with ``hpe evaluate``'s join (:func:`hpe_cli.pipelines.evaluate.join.join`: same key choice, stems, duplicate
checks; no common key is a usage error); the geodesic angle between the two poses with
:func:`hpe_cli.metrics.rotation_errors.geodesic_deg` (what ``hpe evaluate`` reports per row); one thumbnail per
row and one reduced full frame per image (:mod:`.view_thumbs`: parallel, cached by content key); then the page
(:mod:`hpe_cli.report.view_page`). Everything is staged and committed with the run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: key columns tried together with the image name when no --key is given (one image holds several heads)
PERSON_KEYS = ("person_id", "face_id", "head_id")


@dataclass
class Table:
    """One input table, read whole."""

    src: object
    resolved: object
    system: object
    frame: object  # pandas DataFrame of every column
    A: np.ndarray  # (N, 3, 3) canonical; NaN where unusable
    angles: np.ndarray  # (N, 3) pitch, yaw, roll in ``system``
    reasons: np.ndarray  # (N,) object, "" when usable
    lines: np.ndarray | None
    pose_para: bool
    where: object  # row namer

    @property
    def n(self) -> int:
        return len(self.frame)

    def row_numbers(self):
        from .draw_rows import row_numbers

        return row_numbers(self.src, self.lines, np.arange(self.n))


def read_table(path, system, use, radians, option_name="--system") -> Table:
    """Read ``path`` whole: its own system (file metadata, dataset format) else ``system``."""
    from ..io import label_mode, open_table
    from ..io.system_meta import output_system, resolve_system
    from .draw_rows import _read_all, row_namer

    src = open_table(path, with_lines=True)
    resolved = resolve_system(src, system, option_name=option_name, option_is_output=True)
    sys_ = output_system(resolved)
    mode = label_mode(src.columns, src.path, sys_) if use == "auto" else use
    frame, A, angles, reasons, lines = _read_all(src, mode, radians, sys_)
    p = Path(path)
    pose_para = p.is_dir() or p.suffix.lower() == ".mat" or {"tdz", "scale"} <= set(src.columns)
    pose_para = pose_para and not {"bbox_x", "bbox_y"} <= set(src.columns)
    return Table(src, resolved, sys_, frame, A, angles, reasons, lines, pose_para, row_namer(src, lines))


def _key_table(t: Table, keys):
    """The key columns as an Arrow table; a dataset reader's ``file`` also gives ``image`` = its stem."""
    import pyarrow as pa

    cols = {}
    for k in keys:
        if k in t.frame.columns:
            v = t.frame[k]
        elif k == "image" and "file" in t.frame.columns:
            v = t.frame["file"].astype(str).str.replace(r"^.*[\\/]|\.[^.\\/]*$", "", regex=True)
        else:
            continue
        cols[k] = pa.array(v.to_numpy(dtype=object), from_pandas=True)
    return pa.table(cols)


def default_keys(a: Table, b: Table, keys) -> list:
    """``--key`` as given, else evaluate's choice (image, file) plus a person id both tables have."""
    from .evaluate.join import choose_keys

    cols_a, cols_b = list(a.frame.columns), list(b.frame.columns)
    for t, cols in ((a, cols_a), (b, cols_b)):
        if "file" in cols and "image" not in cols and getattr(t.src, "dataset", False):
            cols.append("image")
    chosen = choose_keys(keys, cols_b, cols_a, b.src.path, a.src.path)
    if not keys:
        chosen += [k for k in PERSON_KEYS if k in cols_a and k in cols_b][:1]
    return chosen


def pair(a: Table, b: Table, keys) -> tuple:
    """``(b_idx per row of a (-1: none), unmatched rows of b, keys, notes)`` by :func:`hpe_cli.pipelines.evaluate.join.join`."""
    from .evaluate.join import join
    from .evaluate.sides import Side

    keys = default_keys(a, b, keys)

    def side(t: Table):
        s = Side(
            t.src.path, t.system, "", [np.zeros(0)] * 9, t.reasons == "", None, _key_table(t, keys), None,
            list(t.frame.columns), t.lines if t.lines is not None else np.arange(1, t.n + 1), [],
        )  # fmt: skip
        s.unit = "line" if t.src.unit == "line" else "row"
        return s

    _, bidx, unmatched, notes = join(side(b), side(a), keys)
    return bidx, unmatched, keys, notes


def _placement(t: Table, sizes, img_code):
    """Per row: centre (N, 2), line length (N,), crop (N, 4) or -1, in image pixels."""
    from .draw_rows import DEFAULT_LENGTH_FRACTION, face_placement
    from .view_thumbs import crop_boxes

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
    return centre, L, crop_boxes(boxes)


def _resolve_images(t: Table, root, ok_rows):
    """``(refs of distinct images, code per row (-1: none), reasons per row for missing images)``."""
    import pandas as pd

    from ..io.images import ImageResolver, row_ids
    from ..io.transaction import note_input
    from .draw_rows import _image_names

    n = t.n
    names = _image_names(t.frame)
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


def run_view(
    labels,
    outdir,
    other=None,
    *,
    images=None,
    system=None,
    other_system=None,
    also_in=None,
    radians=False,
    use="auto",
    keys=None,
    workers=1,
    title=None,
    frames=True,
    rejects_path=None,
    strict=False,
    overwrite=False,
    progress=None,
) -> dict:
    """Write a browsable page of every row of ``labels`` (and ``other`` beside it) into folder ``outdir``.

    Parameters
    ----------
    labels, other : str or Path
        Label tables (any reader: Parquet, CSV, text formats, ``.mat`` folders); ``other`` optional.
    outdir : str or Path
        Page folder; ``index.html`` opens from ``file://``. An earlier page there is the thumbnail cache.
    images : str or Path, optional
        Folder the ``image`` column is relative to (default: ``labels``' folder).
    system, other_system : RotationSystem, optional
        Each table's system when its file does not name one (``other_system`` defaults to ``system``);
        the page's angles (degrees) are in ``labels``' system.
    also_in : list of (RotationSystem or str), optional
        Further systems (names or ``.toml`` files) in which every row's angles are computed too, from its
        canonical matrix (the kernels ``hpe convert`` uses); the page's selector makes its angle filters, sort,
        captions and coverage map use one of them.
    radians : bool
        Angle columns in radians (default degrees).
    use : {"auto", "angles", "matrix"}
        Which label columns to read.
    keys : list of str, optional
        Columns pairing ``other``'s rows with ``labels``' (default: ``image`` or ``file``, plus ``person_id``
        when both tables have it).
    workers : int, >= 1
        Threads making the pictures.
    title : str, optional
        Page title (default: ``labels``' file name).
    frames : bool
        Make each image once at most :data:`~hpe_cli.pipelines.view_thumbs.FRAME_SIDE` (960) pixels long for
        the detail view; ``False`` shows the thumbnail there (for datasets of many distinct images).
    rejects_path, strict, overwrite, progress
        As every command (rejects file, any reject an error, replace outputs, a tqdm bar whose total is set).

    Returns
    -------
    dict
        ``rows``, ``shown`` (rows with a thumbnail), ``whole_frame`` (rows without a head box, shown whole),
        ``made`` / ``reused`` (thumbnails made this run / kept from an earlier one), ``pruned`` (files of an
        earlier page in ``outdir`` this one no longer uses, removed with the commit), ``images``, ``matched``
        (rows of ``labels`` with a row of ``other``), ``keys``, ``rejects`` (reason -> count), ``system``,
        ``notes``.
    """
    import hashlib

    from ..errors import HpeError
    from ..io import Rejects
    from ..io.images import image_size
    from ..io.transaction import ensure_transaction, staged_dir
    from ..metrics.rotation_errors import geodesic_deg
    from ..report import view_page
    from . import view_thumbs as vt

    outdir = Path(outdir)
    if (outdir / "index.html").exists() and not overwrite:
        raise HpeError(f"{outdir / 'index.html'}: exists (use --overwrite; thumbnails already made are reused)")
    a = read_table(labels, system, use, radians)
    if a.n == 0:
        raise HpeError(f"{a.src.path}: empty table (no rows)")
    b = read_table(other, other_system or system, use, radians, "--other-system") if other is not None else None
    rejects = Rejects(rejects_path, overwrite, strict=strict, source=a.src)
    ok = a.reasons == ""
    counts: dict = {"rows": a.n}

    # the second table, joined by key
    A_other = np.full_like(a.A, np.nan)
    other_angles = np.full_like(a.angles, np.nan)
    angle = np.full(a.n, np.nan)
    bidx = np.full(a.n, -1, dtype=np.int64)
    notes: list = []
    if b is not None:
        bidx, unmatched, keys, notes = pair(a, b, keys)
        has = bidx >= 0
        has[has] &= b.reasons[bidx[has]] == ""
        A_other[has] = b.A[bidx[has]]
        both = has & ok
        if both.any():
            angle[both] = geodesic_deg(A_other[both], a.A[both])
            if b.system.name == a.system.name:  # the angles as OTHER wrote them
                other_angles[both] = b.angles[bidx[both]]
            else:  # OTHER's pose in LABELS' system, so the two read alike
                other_angles[both] = a.system.to_angles(a.system.from_canonical(A_other[both]))[0]
        bad_b = np.flatnonzero(b.reasons != "")
        if len(bad_b):  # OTHER's rows without a usable pose: kept in the page (no angle), listed as rejects
            rejects.add(
                {"table": np.full(len(bad_b), str(b.src.path), dtype=object), "row": b.row_numbers()[bad_b],
                 **{c: b.frame[c].to_numpy()[bad_b] for c in keys if c in b.frame}},
                b.reasons[bad_b].astype(object),
                where=b.where(int(bad_b[0])),
            )  # fmt: skip
        counts["matched"] = int((bidx >= 0).sum())
        counts["keys"] = keys
        if len(unmatched):
            rejects.add(
                {"table": np.full(len(unmatched), str(b.src.path), dtype=object),
                 "row": b.row_numbers()[unmatched], **{c: b.frame[c].to_numpy()[unmatched] for c in keys
                                                       if c in b.frame}},
                np.full(len(unmatched), f"no row of {a.src.path} with this key", dtype=object),
                where=b.where(int(unmatched[0])),
            )  # fmt: skip

    alt = also_angles(also_in, a.system, a.A, A_other)

    # images, placement, picture names
    root = Path(images) if images else (Path(labels) if Path(labels).is_dir() else Path(labels).parent)
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
    shown = ok & (missing == "")
    fp = vt.fingerprint_all(refs)
    frame_names = [None if not frames else
                   hashlib.blake2b(f"f{vt.VERSION}|{vt.FRAME_SIDE}|{f}".encode(), digest_size=10).hexdigest() + ".jpg"
                   for f in fp]  # fmt: skip
    thumb = np.full(a.n, None, dtype=object)
    idx = np.flatnonzero(shown)
    if len(idx):
        keys_ = vt.picture_keys(np.array(fp, dtype=object)[img_code[idx]], crops[idx], centre[idx], L[idx],
                                a.A[idx], A_other[idx])  # fmt: skip
        thumb[idx] = keys_ + ".jpg"
    counts["whole_frame"] = int((shown & (crops[:, 0] == -1) & (crops[:, 2] == -1)).sum())
    bad = np.flatnonzero(~ok | (missing != ""))
    why = np.where(ok, missing, a.reasons)
    _reject(rejects, a, bad, why[bad])

    if len(rejects) and (rejects.path is None or strict):
        rejects.check()  # fail before making any picture
    have_thumbs, have_frames = vt.existing(outdir, vt.THUMB_DIR), vt.existing(outdir, vt.FRAME_DIR)
    from ..geometry.draw import image_vectors

    V = np.full((a.n, 3, 2), np.nan)
    V[idx] = image_vectors(a.A[idx])[:, :, :2]
    has_other = b is not None and np.isfinite(A_other).any()
    groups: dict = {}
    for i in idx:  # one entry per row to draw, grouped by image
        crop = None if crops[i, 2] == -1 else tuple(crops[i])
        other_i = A_other[i] if has_other else None
        groups.setdefault(int(img_code[i]), []).append((thumb[i], crop, centre[i], float(L[i]), V[i], other_i))
    need_t = set(thumb[idx].tolist()) - have_thumbs
    need_f = set(frame_names) - have_frames - {None}
    with ensure_transaction() as txn, staged_dir(outdir, overwrite) as stage:
        stage = Path(stage)
        vt.mkdirs(stage)
        tasks = vt.make_tasks([(refs[k], frame_names[k], rows) for k, rows in groups.items()], stage, need_t, need_f)
        if progress is not None:
            progress.total = sum(t.n for t in tasks)
            progress.refresh()
        failed = vt.run_tasks(tasks, workers, progress)
        ref_index = {r.key: k for k, r in enumerate(refs)}
        for ref, reason, _ in failed:  # unreadable after all: its rows become rejects
            k = ref_index[ref.key]
            rows = np.flatnonzero((img_code == k) & (thumb != None))  # noqa: E711
            thumb[rows] = None
            _reject(rejects, a, rows, np.full(len(rows), reason, dtype=object))
            why[rows] = reason
        counts["made"] = sum(t.n for t in tasks) - sum(n for _, _, n in failed)
        counts["shown"] = int(sum(t is not None for t in thumb))
        counts["reused"] = counts["shown"] - counts["made"]
        counts["images"] = len(refs)
        if counts["shown"] == 0:
            first = int(bad[0]) if len(bad) else 0
            raise HpeError(f"{a.where(first)}: nothing to show: every row was rejected (first: {why[first]})")
        status = np.where(thumb != None, "ok", why)  # noqa: E711
        view_page.write_page(
            stage,
            title=title or Path(labels).name,
            labels=a,
            other=b,
            bidx=bidx,
            angles=a.angles,
            other_angles=other_angles,
            also=alt,
            angle=angle,
            A=a.A,
            A_other=A_other,
            centre=centre,
            length=L,
            thumbs=thumb,
            frames=[f for f in frame_names],
            sizes=sizes,
            img_code=img_code,
            status=status,
            counts=counts,
        )
        counts["pruned"] = _prune(txn, outdir, thumb, frame_names, failed, refs, view_page.n_chunks(a.n))
        rejects.finish()
    counts["rejects"] = dict(rejects.counts)
    counts["system"] = a.resolved.describe()
    counts["notes"] = notes
    return counts


def _prune(txn, outdir: Path, thumb, frame_names, failed, refs, chunks: int) -> int:
    """Remove, when the run commits, the files an earlier page in ``outdir`` left that this page no longer uses
    (thumbnails of rows dropped or changed, frames of images no longer shown, ``rows/`` files past the last
    chunk). Only names this command writes are considered; anything else in the folder is left alone."""
    import re

    from . import view_thumbs as vt

    bad = {r.key for r, _, _ in failed}
    keep = {
        vt.THUMB_DIR: {t for t in thumb if t is not None},
        vt.FRAME_DIR: {f for f, r in zip(frame_names, refs) if f is not None and r.key not in bad},
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
    from ..rotation.systems import get_system

    out: dict = {}
    for s in systems or []:
        s = get_system(s) if isinstance(s, str) else s
        if s.name == own.name or s.name in out:
            continue
        pair = []
        for M in (A, A_other):
            ang = np.full((len(M), 3), np.nan)
            ok = np.isfinite(M.reshape(len(M), 9)).all(axis=1)
            if ok.any():
                ang[ok] = s.to_angles(s.from_canonical(M[ok]))[0]
            pair.append(ang)
        out[s.name] = tuple(pair)
    return out


def _reject(rejects, t: Table, rows, reasons) -> None:
    if len(rows) == 0:
        return
    cols = {c: t.frame[c].to_numpy()[rows] for c in t.frame.columns if not c.startswith("lm")}
    rejects.add({"row": t.row_numbers()[rows], **cols}, np.asarray(reasons, dtype=object), lines=None)
