"""``hpe evaluate``: read predictions and ground truth, join them, score them, write the outputs.

Both tables are streamed batch by batch; each batch's labels go straight to
canonical matrices (nine float64 columns per side) and only those, the key
columns and the ``--by`` column stay in memory. The join encodes the key columns
with Arrow (dictionary encoding) and pairs rows by numpy indexing; every metric is computed on whole columns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import HpeError

#: key columns tried in order when --key is not given
DEFAULT_KEYS = ("image", "file")


@dataclass
class Side:
    """One input table, read: canonical matrices, usability, keys."""

    path: object
    system: object
    mode: str
    canonical: list  # 9 arrays (N,): the canonical matrix entries, row-major
    ok: np.ndarray  # (N,) bool
    reasons: np.ndarray | None  # (N,) object, '' when usable; None when every row is usable
    keys: object  # pyarrow Table of the key (and --by) columns, or None
    by: np.ndarray | None
    columns: list
    lines: np.ndarray  # (N,) 1-based file line of each row (header = line 1)
    unreadable: list  # rows the reader could not parse: (line, reason)
    raw: np.ndarray | None = None  # (N, 3) the angles as written (degrees), when the side holds angles
    dist: np.ndarray | None = None  # (N,) distance to the nearest rotation (--orthonormalize)
    image_dir: object = None  # folder of a dataset reader whose images sit next to the labels

    @property
    def n(self) -> int:
        return len(self.ok)


def _batch_labels(batch, system, mode, radians, orthonormalize):
    """``(stored soa, ok, reasons, raw angles (n, 3) or None, distance (n,) or None)`` of one batch.

    Angle columns are kept as written (``raw``): the raw-angle protocols compare
    them. With ``orthonormalize`` a matrix that is not a rotation (a network's
    raw output, e.g. TriNet's vectors) is replaced by its nearest rotation
    (SVD, det +1) and ``distance`` is ``||M - R||_F``.
    """
    from ..io import batch_rotations
    from ..io.labels import _native, _value_columns, label_columns_fast

    n = batch.num_rows
    native = _native(system, batch.schema.names)
    if mode == "angles":
        if native and system.storage_kind == "angles":
            cols, ok, reasons = _value_columns(batch, system.value_columns)
            if system.value_units == "radians":
                cols = [c * (180.0 / np.pi) for c in cols]
        else:
            cols, ok, reasons = label_columns_fast(batch, "angles", radians)
        raw = np.stack([np.where(ok, c, 0.0) for c in cols], axis=-1)
        X = system.soa_from_angles(raw[:, 0], raw[:, 1], raw[:, 2])
        X = [[np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)) if np.ndim(v) == 0 else v for v in row]
             for row in X]
        return X, ok, reasons, raw, None
    if orthonormalize and (mode == "matrix" or system.storage_kind == "matrix"):
        from ..metrics.align import project_to_so3_batch

        names = system.value_columns if (native and system.storage_kind == "matrix") else None
        if names is None:
            from ..io import MATRIX_COLS
            names = MATRIX_COLS
        cols, ok, reasons = _value_columns(batch, names)
        M = np.stack([np.where(ok, c, 0.0) for c in cols], axis=-1).reshape(n, 3, 3)
        R, dist = project_to_so3_batch(M)
        bad = ok & ~np.isfinite(dist)
        if bad.any():
            reasons = np.full(n, "", dtype=object) if reasons is None else reasons
            reasons[bad] = "matrix has no nearest rotation (rank < 2)"
            ok &= ~bad
        R[~ok] = np.eye(3)
        return [[R[:, i, j] for j in range(3)] for i in range(3)], ok, reasons, None, np.where(ok, dist, np.nan)
    X, ok, rs = batch_rotations(batch, system, mode, radians)
    return X, ok, rs, None, None


def _stem_key_hook(batch):
    """HOOK (joins by key): a dataset reader with ``file`` but no ``image`` (the ``.mat`` folder reader) gets
    ``image`` = the file stem, so predictions keyed by image name join. Remove once the reader provides it."""
    import pyarrow as pa
    import pyarrow.compute as pc

    names = batch.schema.names
    if "image" in names or "file" not in names:
        return batch
    f = batch.column(names.index("file"))
    stem = pc.replace_substring_regex(pc.cast(f, pa.string()), r"^.*[\\/]|\.[^.\\/]*$", "")
    return pa.RecordBatch.from_arrays(list(batch.columns) + [stem], names=names + ["image"])


def read_side(path, system, use: str, keys, by, radians: bool, batch_size: int, progress=None, role="input",
              orthonormalize=False):
    """Stream one table into a :class:`Side`."""
    import pyarrow as pa

    from ..io import ANGLE_COLS, MATRIX_COLS, label_mode, open_table
    from ..io.readers import LINE_COL
    from ..rotation import soa

    src = open_table(path, batch_size, with_lines=True)
    from ..io.columns import label_system

    system = label_system(src, system)  # .mat Pose_Para is always 300w_lp, whatever --gt-system says
    columns = list(src.columns)
    dataset_stem = "file" in columns and "image" not in columns and getattr(src, "dataset", False)
    if dataset_stem:
        columns.append("image")
    if use == "auto":  # the system's own value columns (rotvec, quaternion, 6-D...) first, then angles, matrix
        mode = label_mode(columns, src.path, system)
    else:
        mode = use
        native = system.storage_kind == mode and all(c in columns for c in system.value_columns)
        need = ANGLE_COLS if mode == "angles" else MATRIX_COLS
        missing = [c for c in need if c not in columns]
        if missing and not native:
            raise HpeError(f"{src.path}: missing column(s) {', '.join(missing)} for --columns {mode}")
    keep = [c for c in dict.fromkeys(list(keys or ()) + ([by] if by and by in columns else [])) if c in columns]
    parts, oks, reasons, key_parts, lines, unreadable, raws, dists = [], [], [], [], [], [], [], []
    any_bad = False
    schema = None
    for batch, bad_rows in src.batches_with_rejects():
        if dataset_stem:
            batch = _stem_key_hook(batch)
        unreadable += [(r.line, r.reason) for r in bad_rows]
        lines.append(batch.column(LINE_COL).to_numpy(zero_copy_only=False).astype(np.int64))
        X, ok, rs, raw, dist = _batch_labels(batch, system, mode, radians, orthonormalize)
        n = batch.num_rows
        X = system.soa_to_canonical(X)
        parts.append(soa.columns(X, n))
        oks.append(ok)
        raws.append(raw)
        dists.append(dist)
        if rs is not None:
            any_bad = True
        reasons.append(rs if rs is not None else n)
        if keep:
            key_parts.append(batch.select(keep))
            schema = key_parts[-1].schema
        if progress is not None:
            progress.update(n)
    canonical = [np.concatenate([p[k] for p in parts]) if parts else np.zeros(0) for k in range(9)]
    ok = np.concatenate(oks) if oks else np.zeros(0, dtype=bool)
    rs_all = None
    if any_bad:
        rs_all = np.concatenate([r if isinstance(r, np.ndarray) else np.full(r, "", dtype=object) for r in reasons])
    table = None
    if keep:
        if key_parts:
            table = pa.Table.from_batches(key_parts, schema=schema)
        else:
            table = pa.schema([src.schema.field(c) if c in src.schema.names else pa.field(c, pa.string())
                               for c in keep]).empty_table()
    by_values = table.column(by).to_numpy() if (by and table is not None and by in table.column_names) else None
    line_arr = np.concatenate(lines) if lines else np.zeros(0, dtype=np.int64)
    side = Side(src.path, system, mode, canonical, ok, rs_all, table, by_values, columns, line_arr, unreadable)
    side.raw = np.concatenate(raws) if raws and all(r is not None for r in raws) else None
    side.dist = np.concatenate(dists) if dists and all(d is not None for d in dists) else None
    side.image_dir = src.path if dataset_stem else None
    return side


class JoinUsageError(HpeError):
    """A join that cannot be made as asked (the CLI turns it into a usage error, exit 2)."""

    exit_code = 2


def _choose_keys(keys, pred_cols, gt_cols, pred_path, gt_path, join_mode="key"):
    if join_mode == "order":
        return []
    if keys:
        for side_cols, p in ((gt_cols, gt_path), (pred_cols, pred_path)):
            bad = [k for k in keys if k not in side_cols]
            if bad:
                raise HpeError(f"{p}: --key column(s) {', '.join(bad)} not in the table; "
                               f"found: {', '.join(side_cols[:20])}")
        return list(keys)
    for k in DEFAULT_KEYS:
        if k in pred_cols and k in gt_cols:
            return [k]
    raise JoinUsageError(f"{pred_path}: no key column shared with {gt_path} (looked for {', '.join(DEFAULT_KEYS)}; "
                         f"prediction columns: {', '.join(pred_cols[:12])}); give --key COL[,COL...], or "
                         "--join order to pair rows by position (only with equal row counts)")


def _stems(arr):
    import pyarrow as pa
    import pyarrow.compute as pc

    return pc.replace_substring_regex(pc.cast(arr, pa.string()), r"^.*[\\/]|\.[^.\\/]*$", "")


def _encode(a, b):
    import pyarrow as pa

    enc = pa.concat_arrays([a, b]).dictionary_encode(null_encoding="encode")
    return enc.indices.to_numpy(zero_copy_only=False).astype(np.int64), len(enc.dictionary)


def _key_codes(gt_keys, pred_keys, keys):
    """One int64 code per row of each side (equal codes iff all key columns are equal) and the notes.

    Text keys that name files are compared as written; when that matches fewer
    rows than comparing their file stems (``image00050.jpg``, ``AFLW/image00050.mat``
    and ``image00050`` are one image), the stems are used and a note says so.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    n_g = gt_keys.num_rows
    code, notes = None, []
    for k in keys:
        a = gt_keys.column(k).combine_chunks()
        b = pred_keys.column(k).combine_chunks()
        if a.type != b.type:  # a key read as numbers on one side and text on the other: compare as text
            a, b = pc.cast(a, pa.string()), pc.cast(b, pa.string())
        c, m = _encode(a, b)
        if pa.types.is_string(a.type) or pa.types.is_large_string(a.type):
            exact = np.isin(c[:n_g], c[n_g:]).sum()
            if exact < min(n_g, len(c) - n_g):
                cs, ms = _encode(_stems(a), _stems(b))
                if np.isin(cs[:n_g], cs[n_g:]).sum() > exact:
                    c, m = cs, ms
                    notes.append(f"key {k!r} joined on file stems (the two files spell the names differently)")
        if code is None:
            code = c
        else:
            code = code * m + c
            code = np.unique(code, return_inverse=True)[1].astype(np.int64).reshape(-1)
    return code[:n_g], code[n_g:], notes


def _where(side, row):
    unit = "row" if str(side.path).lower().endswith((".parquet", ".pq")) else "line"
    if side.image_dir is not None:
        return f"{side.path}"
    return f"{side.path}: {unit} {int(side.lines[row])}"


def _check_unique(codes, side, keys):
    counts = np.bincount(codes) if len(codes) else np.zeros(0, dtype=np.int64)
    dup = counts[codes] > 1
    if dup.any():
        first = int(np.flatnonzero(dup)[0])
        again = int(np.flatnonzero(codes == codes[first])[1])
        what = ", ".join(f"{k}={side.keys.column(k)[first].as_py()!r}" for k in keys)
        unit = "row" if str(side.path).lower().endswith((".parquet", ".pq")) else "line"
        raise HpeError(f"{_where(side, first)}: duplicate key {what} (again at {unit} {int(side.lines[again])}); "
                       f"choose --key columns that identify one row, e.g. --key {','.join(keys)},person_id")


def join(pred: Side, gt: Side, keys, join_mode="key"):
    """``(gt_idx, pred_idx, unmatched prediction rows, notes)``; pred_idx is -1 where a GT row has no prediction."""
    if join_mode == "order":
        if pred.n != gt.n:
            raise JoinUsageError(f"{pred.path}: --join order pairs rows by position and needs equal row counts; "
                                 f"got {pred.n} predictions and {gt.n} ground-truth rows in {gt.path}")
        idx = np.arange(gt.n)
        return idx, idx.copy(), np.zeros(0, dtype=np.int64), ["rows paired by position (--join order)"]
    cg, cp, notes = _key_codes(gt.keys, pred.keys, keys)
    _check_unique(cg, gt, keys)
    _check_unique(cp, pred, keys)
    m = int(max(cg.max(initial=-1), cp.max(initial=-1))) + 1
    pred_pos = np.full(m, -1, dtype=np.int64)
    pred_pos[cp] = np.arange(len(cp))
    gt_has = np.zeros(m, dtype=bool)
    gt_has[cg] = True
    return np.arange(len(cg)), pred_pos[cg], np.flatnonzero(~gt_has[cp]), notes


def _reasons(side: Side, idx):
    if side.reasons is None:
        return np.full(len(idx), "", dtype=object)
    return side.reasons[idx]


def _add_rejects(rej, side, name, rows, reasons, keycols):
    """Rejected rows of ``side`` (its own file and line), the first one named in the error message."""
    if not len(rows):
        return
    unit = "row" if str(side.path).lower().endswith((".parquet", ".pq")) else "line"
    if rej.first_where is None:
        rej.first_where = f"{_where(side, rows[0])}: {reasons[0]}".replace(f"{side.path}: ", "", 0)
        rej.source = side.path
    rej.add({**keycols, "side": np.full(len(rows), name, dtype=object),
             "input": np.full(len(rows), str(side.path), dtype=object), unit: side.lines[rows]},
            np.asarray(reasons, dtype=object))


def _collect_rejects(rej, gt, pred, gidx, pidx, unmatched, key_cols):
    """Send unreadable, missing, invalid and unmatched rows to ``rej``; return the masks over GT rows."""
    missing = pidx < 0
    p_ok = np.where(missing, False, pred.ok[np.maximum(pidx, 0)])
    valid = ~missing & gt.ok[gidx] & p_ok
    invalid = ~missing & ~valid
    for side, name in ((gt, "gt"), (pred, "pred")):
        if side.unreadable:
            ln = np.array([u[0] for u in side.unreadable], dtype=np.int64)
            if rej.first_where is None:
                rej.first_where, rej.source = f"line {ln[0]}: unreadable {name} row: {side.unreadable[0][1]}", side.path
            rej.add({"side": np.full(len(ln), name, dtype=object),
                     "input": np.full(len(ln), str(side.path), dtype=object), "line": ln},
                    np.array([f"unreadable {name} row: {u[1]}" for u in side.unreadable], dtype=object), lines=ln)
    rows = gidx[missing]
    _add_rejects(rej, gt, "gt", rows, np.full(len(rows), "missing: no prediction for this ground-truth row",
                                              dtype=object), key_cols(gt, rows))
    rows, prow = gidx[invalid], pidx[invalid]
    gt_bad = ~gt.ok[rows]
    _add_rejects(rej, gt, "gt", rows[gt_bad], ("invalid: gt " + _reasons(gt, rows[gt_bad])).astype(object),
                 key_cols(gt, rows[gt_bad]))
    _add_rejects(rej, pred, "pred", prow[~gt_bad], ("invalid: prediction " + _reasons(pred, prow[~gt_bad]))
                 .astype(object), key_cols(pred, prow[~gt_bad]))
    _add_rejects(rej, pred, "pred", unmatched, np.full(len(unmatched), "unmatched: prediction with no "
                                                       "ground-truth row", dtype=object), key_cols(pred, unmatched))
    return valid, missing, invalid


def _gather(side, idx):
    """Canonical nested matrix of the rows ``idx`` (no copy when every row is used in its own order)."""
    if len(idx) == side.n and (idx[0] == 0 if len(idx) else True) and np.all(np.diff(idx) == 1):
        return [[side.canonical[3 * i + j] for j in range(3)] for i in range(3)]
    return [[side.canonical[3 * i + j][idx] for j in range(3)] for i in range(3)]


def _open_sides(pred_path, gt_path, pred_system, gt_system, keys, by, use_pred, use_gt, radians, batch_size,
                progress, join_mode, orthonormalize):
    from ..io import open_table

    pcols = open_table(pred_path, batch_size).columns
    gsrc = open_table(gt_path, batch_size)
    gcols = list(gsrc.columns)
    if "file" in gcols and "image" not in gcols and getattr(gsrc, "dataset", False):
        gcols.append("image")  # see _stem_key_hook
    keys = _choose_keys(list(keys or ()), pcols, gcols, pred_path, gt_path, join_mode)
    if by and by not in gcols and by not in pcols:
        raise HpeError(f"{gt_path}: --by column {by!r} is in neither table; found: {', '.join(gcols[:20])}")
    gt = read_side(gt_path, gt_system, use_gt, keys, by, radians, batch_size, progress, "gt")
    pred = read_side(pred_path, pred_system, use_pred, keys, by if by not in gcols else None, radians,
                     batch_size, progress, "pred", orthonormalize=orthonormalize)
    if pred.n == 0 and not pred.unreadable:
        raise HpeError(f"{pred.path}: no prediction rows (the file has a header only)")
    if gt.n == 0 and not gt.unreadable:
        raise HpeError(f"{gt.path}: no ground-truth rows")
    return gt, pred, keys


def run_evaluate(pred_path, gt_path, *, pred_system, gt_system, output=None, keys=(), protocols=None,
                 align="none", by=None, yaw_bins=None, report=None, plots=None, rejects=None, use_pred="auto",
                 use_gt="auto", radians=False, overwrite=False, batch_size=262_144, progress=None,
                 strict=False, join_mode="key", orthonormalize=False, html=None, worst=12, images=None) -> dict:
    """Evaluate ``pred_path`` against ``gt_path``; write the requested outputs; return the report."""
    from ..io import Rejects, write_json
    from ..metrics.evaluate import check_protocols, evaluate_canonical
    from ..metrics.protocols import PROTOCOLS

    try:
        protocols = check_protocols(protocols or None)
    except ValueError as exc:
        raise HpeError(str(exc)) from None
    from ..io.writers import check_report_outputs

    check_report_outputs(report, output, overwrite)
    if html:
        check_report_outputs(html, None, overwrite)
    if plots:
        from ..io.eval_plots import check_plot_outputs

        check_plot_outputs(plots, overwrite)
    rej = Rejects(rejects, overwrite, strict=strict, source=None)
    gt, pred, keys = _open_sides(pred_path, gt_path, pred_system, gt_system, keys, by, use_pred, use_gt, radians,
                                 batch_size, progress, join_mode, orthonormalize)
    gidx, pidx, unmatched, join_notes = join(pred, gt, keys, join_mode)

    def key_cols(side, rows, arrow=False):
        if keys:
            return {k: (side.keys.column(k).take(rows) if arrow else
                        side.keys.column(k).take(rows).to_numpy(zero_copy_only=False)) for k in keys}
        return {"row": rows + 1}

    valid, missing, invalid = _collect_rejects(rej, gt, pred, gidx, pidx, unmatched, key_cols)
    rej.check()  # without --rejects (or with --strict) any set-aside row is an error: nothing is written

    gv, pv = gidx[valid], pidx[valid]
    P, G = _gather(pred, pv), _gather(gt, gv)
    raw = {}
    if gt.raw is not None:
        raw["gt"] = (gt.system, gt.raw[gv])
    if pred.raw is not None:
        raw["pred"] = (pred.system, pred.raw[pv])
    pred.canonical = gt.canonical = None  # the pairs hold their own copies now
    by_values = None
    if by:
        by_values = gt.by[gv] if gt.by is not None else pred.by[pv]
    part, rows = evaluate_canonical(P, G, gt_system=gt_system, protocols=protocols, align=align, by=by_values,
                                    by_name=by or "by", yaw_bins=yaw_bins, raw=raw)
    result = {"n": {"gt": gt.n, "pred": pred.n, "pairs": int(valid.sum()), "missing": int(missing.sum()),
                    "invalid": int(invalid.sum()), "unmatched_pred": len(unmatched)},
              "systems": {"pred": pred.system.name, "gt": gt.system.name}}
    if gt.unreadable or pred.unreadable:
        result["n"]["unreadable"] = len(gt.unreadable) + len(pred.unreadable)
    if pred.dist is not None:
        d = pred.dist[pv]
        result["n"]["orthonormalized"] = int((d > 1e-6).sum())
        result["orthonormalize"] = {"max_distance": float(d.max()) if len(d) else None,
                                    "mean_distance": float(d.mean()) if len(d) else None}
    result.update(part)
    result["inputs"] = {"pred": str(pred.path), "gt": str(gt.path), "key": keys or "row order",
                        "join": join_mode, "columns": {"pred": pred.mode, "gt": gt.mode}}
    result["notes"] = join_notes + [f"{name}: {note}" for name in protocols for note in PROTOCOLS[name].notes]
    if rej.counts:
        result["rejects"] = dict(rej.counts)
    extra = _extra_columns(gt, pred, gv, pv, images)
    if output:
        _write_rows(output, rows, key_cols(gt, gv, arrow=True), by, by_values, gt_system, pred_system, overwrite,
                    batch_size, extra)
    rej.write()
    if plots:
        from ..io.eval_plots import write_eval_plots

        write_eval_plots(plots, rows, result, gt_system, overwrite=overwrite)
    if html:
        from ..report.evaluate_page import write_page

        write_page(html, result, rows, key_cols(gt, gv), extra, overwrite=overwrite, worst=worst)
    if report == "-":
        import click

        from ..io.writers import json_text

        click.echo(json_text(result))
    elif report:
        write_json(result, report, overwrite=overwrite)
    return result


def _extra_columns(gt, pred, gv, pv, images):
    """Per-row extras: the distance to the nearest rotation (--orthonormalize) and the source image path."""
    from pathlib import Path

    extra = {}
    if pred.dist is not None:
        extra["pred_rotation_distance"] = pred.dist[pv]
    folder = Path(images) if images else (Path(gt.image_dir) if gt.image_dir is not None else None)
    if folder is not None and gt.keys is not None and "image" in gt.keys.column_names:
        names = gt.keys.column("image").take(gv).to_pylist()
        paths = []
        for nm in names:
            found = ""
            for ext in ("", ".jpg", ".png", ".jpeg"):
                p = folder / f"{nm}{ext}"
                if p.is_file():
                    found = str(p)
                    break
            paths.append(found)
        if any(paths):
            extra["image_path"] = np.array(paths, dtype=object)
    return extra


def _write_rows(output, rows, keycols, by, by_values, gt_system, pred_system, overwrite, batch_size, extra=None):
    """One row per valid pair: keys, both labels in the GT system, per-angle errors, geodesic, maev."""
    import pyarrow as pa

    from ..io import TableWriter, system_metadata

    cols = dict(keycols)
    if by and by not in cols:
        cols[by] = by_values
    for k, a in enumerate(("pitch", "yaw", "roll")):
        cols[f"gt_{a}"] = rows.gt_angles[:, k]
    for k, a in enumerate(("pitch", "yaw", "roll")):
        cols[f"pred_{a}"] = rows.pred_angles[:, k]
    for k, a in enumerate(("pitch", "yaw", "roll")):
        cols[f"err_{a}"] = rows.mae_wrapped[:, k]
    cols["geodesic"] = rows.geodesic
    for k, a in enumerate(("left", "down", "front")):
        cols[f"maev_{a}"] = rows.maev[:, k]
    cols["frobenius"] = rows.frobenius
    cols.update(extra or {})
    meta = {**system_metadata(gt_system), "hpe:evaluate_pred_system": pred_system.name,
            "hpe:evaluate_note": "gt_* and pred_* are angles in the GT system (primary solution; pred after "
                                 "--align); err_* are "
                                 "wrapped |pred - gt| in [0, 180]; geodesic and maev_* in degrees"}
    n = rows.n
    arrays = {k: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else pa.array(v)) for k, v in cols.items()}
    table = pa.table(arrays)
    with TableWriter(output, overwrite, meta) as w:
        if n == 0:
            w.write(table)
        for start in range(0, n, batch_size):
            w.write(table.slice(start, batch_size))
