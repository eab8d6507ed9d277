"""``hpe draw`` on the per-row output of ``hpe evaluate -o``: ground truth and prediction on the same face.

Ground truth is drawn with solid lines, the prediction with dashed, thinner lines ending in a dot (both in the
axis colours: red = the subject's left, green = forehead to chin, blue = out of the nose); a legend in the
top-left corner says which is which, and the error (``--sort-by`` column, and the geodesic error) is written in
the top-right corner. One PNG per row, named ``<rank>_<image stem>.png`` (rank 1 = worst), so two rows of one
image never share an output file.

:func:`draw_worst` writes the PNGs, :func:`render_worst` yields the same pictures as arrays (the evaluate
page embeds them), both as :class:`WorstOptions` say; :func:`run_draw_errors` is ``hpe draw``'s job.
"""

from __future__ import annotations

import itertools
import re
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ...datasets.mat import read_mat
from ...errors import HpeError
from ...geometry import draw as g
from ...io import Rejects, open_table
from ...io.images import ImageResolver, row_ids
from ...io.readers import LINE_COL
from ...io.rejects import fail_all_rejected
from ...io.system_meta import system_from_metadata
from ...io.transaction import ensure_transaction, note_input, staged_dir
from ...rotation import get_system
from ...rotation.systems import canonical_system
from .rows import (
    DEFAULT_LENGTH_FRACTION,
    MAT_LENGTH_UNITS,
    face_placement,
    image_names,
    row_namer,
    row_numbers,
    write_image,
)

#: columns ``hpe evaluate -o`` writes besides its key columns
ANGLE_COLUMNS = ("gt_pitch", "gt_yaw", "gt_roll", "pred_pitch", "pred_yaw", "pred_roll")
_EVAL_COLUMNS = set(ANGLE_COLUMNS) | {
    "err_pitch",
    "err_yaw",
    "err_roll",
    "geodesic",
    "maev_left",
    "maev_down",
    "maev_front",
    "frobenius",
    "row",
}
_PLACEMENT = {"bbox_x", "bbox_y", "bbox_w", "bbox_h", "tdx", "tdy", "tdz", "size", "scale"}
GT_STYLE = "solid"
PRED_STYLE = "dashed"
#: what a row whose image is not found (or not readable) becomes
ON_MISSING = ("canvas", "error", "skip")


@dataclass(frozen=True)
class WorstOptions:
    """Which rows of evaluate's output :func:`draw_worst` / :func:`render_worst` draw, and how.

    Attributes
    ----------
    worst : int, optional
        Draw only the ``worst`` rows (>= 1) with the largest ``sort_by`` (all rows when None).
    sort_by : str
        Numeric column to sort by, largest first (NaN last); default ``geodesic``.
    on_missing : {"canvas", "error", "skip"}
        A row whose image is not found (or cannot be read) is drawn on a grey canvas that says so, is an
        error, or is left out and listed in the caller's ``skipped``.
    thickness : int, optional
        Line thickness of the ground truth in pixels (default: from the length).
    where : str, optional
        The table's name in messages (default: the file, else ``"evaluate output"``).
    row_name : callable, optional
        ``row_name(i)`` names 0-based row ``i`` in messages (default ``"<where>: row <i + 1>"``).
    """

    worst: int | None = None
    sort_by: str = "geodesic"
    on_missing: str = "canvas"
    thickness: int | None = None
    where: str | None = None
    row_name: Callable | None = None

    def __post_init__(self):
        if self.on_missing not in ON_MISSING:
            raise HpeError(f"on_missing: expected one of {', '.join(ON_MISSING)}, got {self.on_missing!r}")
        if self.worst is not None and not (isinstance(self.worst, int) and self.worst >= 1):
            raise HpeError(f"worst: expected an integer >= 1, got {self.worst!r}")

    @classmethod
    def of(cls, settings: dict) -> WorstOptions:
        """``settings["options"]`` (a :class:`WorstOptions`) when that is the one setting, else
        ``WorstOptions(**settings)``."""
        if set(settings) == {"options"}:
            return settings["options"]
        return cls(**settings)


def is_errors_table(columns) -> bool:
    """True for a table written by ``hpe evaluate -o`` (it has ``gt_*`` and ``pred_*`` angles)."""
    return all(c in columns for c in ANGLE_COLUMNS)


def key_columns(columns) -> list:
    """The columns that identify a row of evaluate's output (its ``--key`` columns, else ``row``)."""
    keys = [c for c in columns if c not in _EVAL_COLUMNS and c not in _PLACEMENT]
    return keys or (["row"] if "row" in columns else [])


def table_system(schema, default):
    """The system a Parquet file's metadata names (:func:`~hpe_cli.io.system_meta.system_from_metadata`), else
    ``default``; and where it came from."""
    try:
        found = system_from_metadata(getattr(schema, "metadata", None))
    except HpeError:  # a custom system whose TOML is not at hand: the given one
        return default, "option (the file's system is not known here)"
    return (found, "file metadata") if found is not None else (default, "option")


def _order(frame, sort_by, worst, where):
    if sort_by not in frame.columns:
        numeric = [c for c in frame.columns if pd.api.types.is_numeric_dtype(frame[c])]
        raise HpeError(
            f"{where}: --sort-by {sort_by!r}: expected one of the numeric columns "
            f"{', '.join(numeric)}, got no column of that name"
        )

    v = pd.to_numeric(frame[sort_by], errors="coerce").to_numpy(np.float64)
    if np.isnan(v).all() and len(v):
        raise HpeError(f"{where}: --sort-by {sort_by!r}: expected a numeric column, got no numbers")
    order = np.argsort(np.where(np.isnan(v), -np.inf, -v), kind="stable")  # worst first, NaN last
    return order[:worst] if worst else order


def _placement(frame, idx, ref, H, W):
    """Head centre (u, v) and line length for row ``idx``: the table's box/tdx, else the ``.mat`` beside the
    image (Pose_Para tdx, tdy from the bottom, length 100000 * scale), else the image centre."""
    c, L, _ = face_placement(frame.iloc[[idx]], pose_para=False)
    if np.isfinite(c[0]).all():
        return c[0], (L[0] if np.isfinite(L[0]) else DEFAULT_LENGTH_FRACTION * min(H, W))
    if ref is not None and ref.path is not None:
        mat = Path(ref.path).with_suffix(".mat")
        if mat.is_file():
            try:
                pose = read_mat(mat)["pose"]
            except HpeError:
                pose = None
            if pose is not None and np.isfinite(pose[3:5]).all():
                L0 = abs(pose[6]) * MAT_LENGTH_UNITS if np.isfinite(pose[6]) and pose[6] != 0 else np.nan
                return np.array([pose[3], H - 1 - pose[4]]), (
                    L0 if np.isfinite(L0) else DEFAULT_LENGTH_FRACTION * min(H, W)
                )
    return np.array([W / 2.0, H / 2.0]), DEFAULT_LENGTH_FRACTION * min(H, W)


def render_pair(img, A_gt, A_pred, centre, length, corner_text, thickness=None):
    """Draw ground truth (solid) and prediction (dashed, dot at each end) on ``img``, a legend top-left and
    ``corner_text`` (lines) top-right. In place; returns ``img``."""
    t = thickness or g.auto_thickness(length)
    c = np.asarray(centre, dtype=np.float64).reshape(1, 2)
    g.render_axes(img, A_gt[None], c, length, t)
    g.render_axes_dashed(img, A_pred[None], c, length, max(1, (t + 1) // 2))
    H, W = img.shape[:2]
    g.render_legend(img, [("ground truth", GT_STYLE), ("prediction", PRED_STYLE)], max(12.0, 0.035 * min(H, W)))
    h = max(12.0, 0.035 * min(H, W))
    for k, line in enumerate(corner_text):
        g.render_caption(img, line, (W, (k + 1) * (h * 1.5)), height_px=h)
    return img


def draw_worst(rows, *, images, out_dir, system=None, overwrite=False, progress=None, skipped=None, **settings):
    """Draw the worst rows of ``hpe evaluate -o``'s output, ground truth and prediction on the same face.

    Parameters
    ----------
    rows : pandas.DataFrame or str or Path
        The per-row output of ``hpe evaluate -o`` (a DataFrame, or the file). Needs ``gt_pitch, gt_yaw,
        gt_roll, pred_pitch, pred_yaw, pred_roll`` (degrees, in the ground truth's system), the column
        ``sort_by``, and a key column naming the image (``image``, ``file``, ... or Panoptic ``sequence,
        camera, frame``).
    images : str or Path
        Folder the image names are relative to (see :mod:`hpe_cli.io.images`).
    out_dir : str or Path
        Folder for the PNGs; created; staged and committed with the run (:func:`hpe_cli.io.transaction.staged_dir`).
    system : str or RotationSystem, optional
        System of the ``gt_*``/``pred_*`` angles; default: the file's ``hpe:system`` metadata (or
        ``rows.attrs["hpe:system"]``), else ``300w_lp``.
    overwrite : bool
        Replace PNGs of an earlier run.
    progress : tqdm, optional
        A bar whose total is set to the number of rows drawn.
    skipped : list, optional
        With ``on_missing="skip"``: ``(row index, reason)`` is appended for each row left out.
    **settings
        :class:`WorstOptions` fields (``worst``, ``sort_by``, ``on_missing``, ``thickness``, ``where``,
        ``row_name``), or ``options=WorstOptions(...)``.

    Returns
    -------
    list of (key, path, caption)
        One per drawn row, worst first: ``key`` a tuple of the row's key-column values
        (:func:`key_columns`), ``path`` the written PNG (a :class:`~pathlib.Path` in ``out_dir``),
        ``caption`` one line (key, error, both angle triples).
    """
    options = WorstOptions.of(settings)
    out_dir = Path(out_dir)
    done = {}
    with ensure_transaction(), staged_dir(out_dir, overwrite) as stage:
        drawn = render_worst(rows, images=images, system=system, progress=progress, skipped=skipped, options=options)
        for rank, _, img, key, caption, stem in drawn:
            rel = Path(f"{rank + 1:04d}_{_safe_stem(stem)}.png")
            write_image(img, stage / rel, out_dir / rel)
            done[rank] = (key, out_dir / rel, caption)
    return [done[k] for k in sorted(done)]


def render_worst(rows, *, images, system=None, progress=None, skipped=None, crop=None, **settings):
    """The pictures :func:`draw_worst` writes, as arrays, without writing anything (the evaluate page embeds them).

    Same parameters as :func:`draw_worst` (no ``out_dir``). Yields ``(rank, row, image, key, caption, stem)`` for
    each drawn row: ``rank`` 0 = worst, ``row`` the 0-based row of ``rows``, ``image`` a BGR ``uint8`` array,
    ``stem`` the image's file stem. Image files come in rank order, then the frames of each video (decoded
    once), so one picture is in memory at a time. ``crop(image, row)`` -> ``(part, (x0, y0))`` cuts each
    picture before drawing (the evaluate page: around the face of a large frame); the poses are drawn at the
    row's centre moved by ``(x0, y0)``.
    """
    options = WorstOptions.of(settings)
    rows, system, where = _load(rows, system, options.where)
    row_name = options.row_name or (lambda i: f"{where}: row {i + 1}")
    skipped = [] if skipped is None else skipped
    order = _order(rows, options.sort_by, options.worst, where)
    names = image_names(rows) or [None] * len(rows)
    job = _Pairs(rows, system, options.sort_by, names, options.thickness)
    refs = _find_all(rows, names, order, images, options.on_missing, skipped, row_name)
    if progress is not None:
        progress.total = len(order)
        progress.refresh()
    found = [k for k, r in enumerate(refs) if r is not None]
    on_canvas = options.on_missing == "canvas"
    missing = ((k, None, "image not found") for k, r in enumerate(refs) if r is None and on_canvas)
    pictures = ((found[k], img, why) for k, img, why in ImageResolver.read([refs[k] for k in found]))
    for rank, img, why in itertools.chain(missing, pictures):
        i = int(order[rank])
        if img is None and options.on_missing == "error":
            raise HpeError(f"{row_name(i)}: {why}")
        if img is None and options.on_missing == "skip":
            skipped.append((i, why))
            continue
        off = (0, 0)
        if crop is not None and img is not None:
            img, off = crop(img, i)
        img, key, caption = job.draw(img, why, i, refs[rank], off)
        yield rank, i, img, key, caption, Path(str(names[i] or f"row{i + 1}")).stem
        if progress is not None:
            progress.update(1)


def _find_all(rows, names, order, images, on_missing, skipped, row_name):
    """The picture of each row of ``order`` (None when not found: an error, a skipped row or a canvas)."""
    seqs, cams, frs = row_ids(rows)
    resolver = ImageResolver(images)
    refs = []
    for i in order.tolist():
        ref = resolver.find(names[i], seqs[i], cams[i], frs[i]) if (names[i] or cams[i]) else None
        if ref is None and on_missing != "canvas":
            why = f"image not found: {resolver.tried(names[i], seqs[i])}"
            if on_missing == "error":
                raise HpeError(f"{row_name(i)}: {why}")
            skipped.append((i, why))
        if ref is not None:
            note_input(ref.path or ref.video)
        refs.append(ref)
    return refs


def _load(rows, system, where):
    """(DataFrame, RotationSystem, name for messages) of a DataFrame or a Parquet/CSV file of evaluate's output."""
    if not isinstance(rows, pd.DataFrame):
        path = Path(rows)
        note_input(path)
        if path.suffix.lower() in (".parquet", ".pq"):
            table = pq.read_table(path)
            if system is None:
                system, _ = table_system(table.schema, canonical_system())
            rows = table.to_pandas()
        else:
            rows = pd.read_csv(path)
        where = where or str(path)
    where = where or "evaluate output"
    if system is None:
        system = rows.attrs.get("hpe:system", canonical_system())
    system = get_system(system) if isinstance(system, str) else system
    missing = [c for c in ANGLE_COLUMNS if c not in rows.columns]
    if missing:
        raise HpeError(
            f"{where}: expected hpe evaluate's per-row output with {', '.join(ANGLE_COLUMNS)}, "
            f"missing {', '.join(missing)}"
        )
    return rows, system, where


class _Pairs:
    """Draws one row of evaluate's output: both poses, legend, error (the caller writes or embeds it)."""

    def __init__(self, rows, system, sort_by, names, thickness):
        self.rows, self.system, self.sort_by, self.names, self.thickness = rows, system, sort_by, names, thickness
        self.keys = key_columns(rows.columns)
        self.gt = rows[list(ANGLE_COLUMNS[:3])].to_numpy(np.float64)
        self.pr = rows[list(ANGLE_COLUMNS[3:])].to_numpy(np.float64)
        self.ok = np.isfinite(self.gt).all(1) & np.isfinite(self.pr).all(1)
        self.A_gt = np.full((len(rows), 3, 3), np.nan)
        self.A_pr = np.full((len(rows), 3, 3), np.nan)
        ok = self.ok
        self.A_gt[ok] = system.to_canonical(system.from_angles(self.gt[ok]))
        self.A_pr[ok] = system.to_canonical(system.from_angles(self.pr[ok]))

    def draw(self, img, why, i, ref, offset=(0, 0)):
        rows, sort_by, gt, pr = self.rows, self.sort_by, self.gt, self.pr
        if img is None:
            img = g.blank_canvas(320, 320, 96)
            g.render_caption(img, f"{why[:48]}", (4, 310), height_px=11)
        H, W = img.shape[:2]
        key = tuple(rows[k].iat[i] for k in self.keys)
        err = float(rows[sort_by].iat[i])
        corner = [f"{sort_by} {err:.2f}" + (" deg" if sort_by != "frobenius" else "")]
        if sort_by != "geodesic" and "geodesic" in rows.columns:
            corner.append(f"geodesic {float(rows['geodesic'].iat[i]):.2f} deg")
        if self.ok[i]:
            centre, length = _placement(rows, i, ref, H + offset[1], W + offset[0])
            centre = np.asarray(centre, dtype=np.float64) - np.asarray(offset, dtype=np.float64)
            render_pair(img, self.A_gt[i], self.A_pr[i], centre, length, corner, self.thickness)
        else:
            g.render_caption(img, "angles missing", (4, H - 6), height_px=14)
        caption = (
            f"{', '.join(map(str, key))}: {sort_by} {err:.2f}; gt (p, y, r) = "
            f"({gt[i, 0]:.1f}, {gt[i, 1]:.1f}, {gt[i, 2]:.1f}), pred = "
            f"({pr[i, 0]:.1f}, {pr[i, 1]:.1f}, {pr[i, 2]:.1f}) deg in {self.system.name}"
        )
        return img, key, caption


def _safe_stem(stem: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", stem)[:80] or "image"


def run_draw_errors(input_path, outdir, options, *, progress=None) -> dict:
    """``hpe draw`` on evaluate's output (``options`` a :class:`~hpe_cli.pipelines.draw.DrawOptions`): a row
    whose image is missing is a reject (an error without ``--rejects`` or with ``strict``); a run that draws
    nothing exits 1. Rows are named as the input numbers them."""
    input_path = Path(input_path)
    src, frame, lines = _read_errors(input_path)
    system, source = options.system, "option"
    if input_path.suffix.lower() in (".parquet", ".pq"):
        system, source = table_system(pq.read_schema(input_path), system)
    if system is None:
        system, source = canonical_system(), "default"
    if len(frame) == 0:
        raise HpeError(f"{input_path}: empty table (no rows)")
    where = row_namer(src, lines)
    rejects = Rejects(options.rejects, options.overwrite, strict=options.strict, source=input_path)
    skip = options.rejects is not None and not options.strict
    worst = WorstOptions(
        worst=options.worst,
        sort_by=options.sort_by or "geodesic",
        on_missing="skip" if skip else "error",
        thickness=options.thickness,
        where=str(input_path),
        row_name=where,
    )
    skipped: list = []
    with ensure_transaction():
        res = draw_worst(
            frame,
            images=options.images or input_path.parent,
            out_dir=outdir,
            system=system,
            overwrite=options.overwrite,
            progress=progress,
            skipped=skipped,
            options=worst,
        )
        _reject_skipped(rejects, skipped, (src, input_path), frame, lines, drawn=len(res))
        rejects.finish()
    return {
        "faces": len(res),
        "images": len(res),
        "sheets": 0,
        "rejects": dict(Counter(w.split(":")[0] for _, w in skipped)),
        "system": system.name,
        "system_source": source,
        "drawn": res,
    }


def _read_errors(input_path):
    """``(TableSource, DataFrame, line numbers or None)`` of evaluate's output, read whole."""
    src = open_table(input_path, with_lines=True)
    table = pa.Table.from_batches(list(src.batches()), schema=src.schema)
    lines = table.column(LINE_COL).to_numpy() if LINE_COL in table.column_names else None
    frame = table.drop_columns([LINE_COL]).to_pandas() if lines is not None else table.to_pandas()
    return src, frame, lines


def _reject_skipped(rejects, skipped, table, frame, lines, drawn):
    """The rows left out (image not found) into ``rejects``; a run that drew none of its rows is an error.
    ``table``: ``(TableSource, the path as given)``."""
    if not skipped:
        return
    src, path = table
    skipped.sort()
    idx = np.array([i for i, _ in skipped], dtype=np.int64)
    why = [w for _, w in skipped]
    rejects.add(
        {"row": row_numbers(src, lines, idx), **{c: frame[c].to_numpy()[idx] for c in frame.columns}},
        why,
        lines=np.asarray(lines)[idx] if src.kind == "csv" and lines is not None else None,
    )
    if not drawn:  # the rejects file is still written: it says why
        where = row_namer(src, lines)
        fail_all_rejected(
            rejects,
            f"{path}: nothing drawn: all {len(idx)} row(s) rejected "
            f"(first: {where(int(idx[0])).split(': ', 1)[-1]}: {why[0]})",
        )
