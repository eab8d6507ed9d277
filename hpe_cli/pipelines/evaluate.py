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
    where: object = None  # names a row number: "FILE: line N" / "FILE: row N" / "FILE" (TableSource.where)

    @property
    def n(self) -> int:
        return len(self.ok)


def read_side(path, system, use: str, keys, by, radians: bool, batch_size: int, progress=None, role="input"):
    """Stream one table into a :class:`Side`."""
    import pyarrow as pa

    from ..io import ANGLE_COLS, MATRIX_COLS, batch_rotations, label_mode, open_table
    from ..io.readers import LINE_COL
    from ..rotation import soa

    src = open_table(path, batch_size, with_lines=True)
    from ..io.system_meta import resolve_system

    system = resolve_system(src, system, default=None, option_name=f"--{role}-system", option_is_output=True).system
    columns = src.columns
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
    parts, oks, reasons, key_parts, lines, unreadable = [], [], [], [], [], []
    any_bad = False
    for batch, bad_rows in src.batches_with_rejects():
        unreadable += [(r.line, r.reason) for r in bad_rows]
        lines.append(batch.column(LINE_COL).to_numpy(zero_copy_only=False).astype(np.int64))
        X, ok, rs = batch_rotations(batch, system, mode, radians)
        n = batch.num_rows
        X = system.soa_to_canonical(X)
        parts.append(soa.columns(X, n))
        oks.append(ok)
        if rs is not None:
            any_bad = True
        reasons.append(rs if rs is not None else n)
        if keep:
            key_parts.append(batch.select(keep))
        if progress is not None:
            progress.update(n)
    canonical = [np.concatenate([p[k] for p in parts]) if parts else np.zeros(0) for k in range(9)]
    ok = np.concatenate(oks) if oks else np.zeros(0, dtype=bool)
    rs_all = None
    if any_bad:
        rs_all = np.concatenate([r if isinstance(r, np.ndarray) else np.full(r, "", dtype=object) for r in reasons])
    table = None
    if keep:
        table = pa.Table.from_batches(key_parts, schema=pa.schema([src.schema.field(c) for c in keep])) \
            if key_parts else pa.schema([src.schema.field(c) for c in keep]).empty_table()
    by_values = table.column(by).to_numpy() if (by and table is not None and by in table.column_names) else None
    line_arr = np.concatenate(lines) if lines else np.zeros(0, dtype=np.int64)
    return Side(src.path, system, mode, canonical, ok, rs_all, table, by_values, columns, line_arr, unreadable,
                src.where)


def _choose_keys(keys, pred_cols, gt_cols, pred_path, gt_path):
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
    return []


def _key_codes(gt_keys, pred_keys, keys):
    """One int64 code per row of each side; equal codes iff all key columns are equal (Arrow hashing)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    n_g = gt_keys.num_rows
    code = None
    for k in keys:
        a = gt_keys.column(k).combine_chunks()
        b = pred_keys.column(k).combine_chunks()
        if a.type != b.type:  # a key read as numbers on one side and text on the other: compare as text
            a, b = pc.cast(a, pa.string()), pc.cast(b, pa.string())
        enc = pa.concat_arrays([a, b]).dictionary_encode(null_encoding="encode")
        c = enc.indices.to_numpy(zero_copy_only=False).astype(np.int64)
        m = len(enc.dictionary)
        if code is None:
            code = c
        else:
            code = code * m + c
            code = np.unique(code, return_inverse=True)[1].astype(np.int64).reshape(-1)
    return code[:n_g], code[n_g:]


def _check_unique(codes, table, keys, side):
    counts = np.bincount(codes)
    dup = counts[codes] > 1
    if dup.any():
        first = int(np.flatnonzero(dup)[0])
        again = int(np.flatnonzero(codes == codes[first])[1])
        what = ", ".join(f"{k}={table.column(k)[first].as_py()!r}" for k in keys)
        raise HpeError(f"{side.where(side.lines[first])}: duplicate key {what} (again at "
                       f"{side.where(side.lines[again]).split(': ', 1)[-1]}); "
                       f"choose --key columns that identify one row, e.g. --key {','.join(keys)},person_id")


def join(pred: Side, gt: Side, keys):
    """Index arrays ``(gt_idx, pred_idx)`` (pred_idx -1 where missing) and the unmatched prediction rows."""
    if not keys:
        if pred.n != gt.n:
            raise HpeError(f"{pred.path}: {pred.n} rows but {gt.path} has {gt.n}: without a shared 'image' or "
                           "'file' column rows are paired by order, which needs equal counts; give --key COLUMN")
        idx = np.arange(gt.n)
        return idx, idx.copy(), np.zeros(0, dtype=np.int64)
    cg, cp = _key_codes(gt.keys, pred.keys, keys)
    _check_unique(cg, gt.keys, keys, gt)
    _check_unique(cp, pred.keys, keys, pred)
    m = int(max(cg.max(initial=-1), cp.max(initial=-1))) + 1
    pred_pos = np.full(m, -1, dtype=np.int64)
    pred_pos[cp] = np.arange(len(cp))
    gt_has = np.zeros(m, dtype=bool)
    gt_has[cg] = True
    return np.arange(len(cg)), pred_pos[cg], np.flatnonzero(~gt_has[cp])


def _reasons(side: Side, idx):
    if side.reasons is None:
        return np.full(len(idx), "", dtype=object)
    return side.reasons[idx]


def run_evaluate(pred_path, gt_path, *, pred_system, gt_system, output=None, keys=(), protocols=None,
                 align="none", by=None, yaw_bins=None, report=None, plots=None, rejects=None, use_pred="auto",
                 use_gt="auto", radians=False, overwrite=False, batch_size=262_144, progress=None,
                 strict=False) -> dict:
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
    if plots:
        from ..io.eval_plots import check_plot_outputs

        check_plot_outputs(plots, overwrite)
    rej = Rejects(rejects, overwrite, strict=strict, source=gt_path)

    from ..io import open_table

    pcols = open_table(pred_path, batch_size).columns
    gcols = open_table(gt_path, batch_size).columns
    keys = _choose_keys(list(keys or ()), pcols, gcols, pred_path, gt_path)
    if by and by not in gcols and by not in pcols:
        raise HpeError(f"{gt_path}: --by column {by!r} is in neither table; found: {', '.join(gcols[:20])}")
    gt = read_side(gt_path, gt_system, use_gt, keys, by, radians, batch_size, progress, "gt")
    pred = read_side(pred_path, pred_system, use_pred, keys, by if by not in gcols else None, radians,
                     batch_size, progress, "pred")
    gt_system, pred_system = gt_system or gt.system, pred_system or pred.system  # the files' own when not given
    gidx, pidx, unmatched = join(pred, gt, keys)

    missing = pidx < 0
    g_ok = gt.ok[gidx]
    p_ok = np.where(missing, False, pred.ok[np.maximum(pidx, 0)])
    valid = ~missing & g_ok & p_ok
    invalid = ~missing & ~valid

    def key_cols(side, rows, arrow=False):
        if keys:
            return {k: (side.keys.column(k).take(rows) if arrow else
                        side.keys.column(k).take(rows).to_numpy(zero_copy_only=False)) for k in keys}
        return {"row": rows + 1}

    for side, name in ((gt, "gt"), (pred, "pred")):
        if side.unreadable:
            ln = np.array([u[0] for u in side.unreadable], dtype=np.int64)
            rej.add({"side": np.full(len(ln), name, dtype=object), "input": np.full(len(ln), str(side.path),
                                                                                    dtype=object), "line": ln},
                    np.array([f"unreadable {name} row: {u[1]}" for u in side.unreadable], dtype=object), lines=ln,
                    where=side.where)
    if missing.any():
        rows = gidx[missing]
        rej.add({**key_cols(gt, rows), "side": np.full(len(rows), "gt", dtype=object),
                 "input": np.full(len(rows), str(gt.path), dtype=object), "line": gt.lines[rows]},
                np.full(len(rows), "missing: no prediction for this ground-truth row", dtype=object),
                where=gt.where(gt.lines[rows[0]]))
    if invalid.any():
        rows = gidx[invalid]
        prow = pidx[invalid]
        gt_bad = ~gt.ok[rows]
        why = np.where(gt_bad, "invalid: gt " + _reasons(gt, rows), "invalid: prediction " + _reasons(pred, prow))
        rej.add({**key_cols(gt, rows), "side": np.where(gt_bad, "gt", "pred").astype(object),
                 "input": np.where(gt_bad, str(gt.path), str(pred.path)).astype(object),
                 "line": np.where(gt_bad, gt.lines[rows], pred.lines[prow])}, why.astype(object),
                where=gt.where(gt.lines[rows[0]]) if gt_bad[0] else pred.where(pred.lines[prow[0]]))
    if len(unmatched):
        rej.add({**key_cols(pred, unmatched), "side": np.full(len(unmatched), "pred", dtype=object),
                 "input": np.full(len(unmatched), str(pred.path), dtype=object), "line": pred.lines[unmatched]},
                np.full(len(unmatched), "unmatched: prediction with no ground-truth row", dtype=object),
                where=pred.where(pred.lines[unmatched[0]]))
    rej.check()  # without --rejects (or with --strict) any set-aside row is an error: nothing is written

    gv, pv = gidx[valid], pidx[valid]
    def gather(side, idx):  # no copy when every row is used in its own order
        if len(idx) == side.n and (idx[0] == 0 if len(idx) else True) and np.all(np.diff(idx) == 1):
            return [[side.canonical[3 * i + j] for j in range(3)] for i in range(3)]
        return [[side.canonical[3 * i + j][idx] for j in range(3)] for i in range(3)]

    P = gather(pred, pv)
    G = gather(gt, gv)
    pred.canonical = gt.canonical = None  # the pairs hold their own copies now
    by_values = None
    if by:
        by_values = gt.by[gv] if gt.by is not None else pred.by[pv]
    part, rows = evaluate_canonical(P, G, gt_system=gt_system, protocols=protocols, align=align, by=by_values,
                                    by_name=by or "by", yaw_bins=yaw_bins)
    result = {"n": {"gt": gt.n, "pred": pred.n, "pairs": int(valid.sum()), "missing": int(missing.sum()),
                    "invalid": int(invalid.sum()), "unmatched_pred": int(len(unmatched))},
              "systems": {"pred": pred_system.name, "gt": gt_system.name}}
    result.update(part)
    result["inputs"] = {"pred": str(pred.path), "gt": str(gt.path), "key": keys or "row order",
                        "columns": {"pred": pred.mode, "gt": gt.mode}}
    result["notes"] = [f"{name}: {note}" for name in protocols for note in PROTOCOLS[name].notes]
    if rej.counts:
        result["rejects"] = dict(rej.counts)

    if output:
        _write_rows(output, rows, key_cols(gt, gidx[valid], arrow=True),
                    by, by_values, gt_system, pred_system, overwrite, batch_size)
    rej.write()
    if plots:
        from ..io.eval_plots import write_eval_plots

        write_eval_plots(plots, rows, result, gt_system, overwrite=overwrite)
    if report == "-":
        import click

        from ..io.writers import json_text

        click.echo(json_text(result))
    elif report:
        write_json(result, report, overwrite=overwrite)
    return result


def _write_rows(output, rows, keycols, by, by_values, gt_system, pred_system, overwrite, batch_size):
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
