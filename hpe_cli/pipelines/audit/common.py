"""The audit package's shared internals: the notes, statistics and suspects list of ``hpe audit --consistency``
(:mod:`hpe_cli.pipelines.audit.consistency`), shared by its modules."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from ...io.layout import arrow_to_numpy


def _r(v):
    return None if not np.isfinite(v) else round(float(v), 3)


def _stats(x) -> dict:
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return {"n": 0}
    q = np.percentile(x, [50, 90, 99])
    return {"n": int(x.size), "median": _r(q[0]), "p90": _r(q[1]), "p99": _r(q[2]), "max": _r(x.max())}


def suspects_table(cons, batches, order, key_cols):
    """The suspects key list, highest score first: key columns, ``row``, ``score``, ``reason`` (what
    ``--exclude`` reads).

    ``order``: the suspects' global row indices (:meth:`ConsistencyAudit.worst_order`);
    ``batches``: the input again (at least ``key_cols``), in input order. The key
    columns are taken from each batch as Arrow arrays (no Python object per value).
    """

    idx = np.asarray(order, dtype=np.int64)
    by_row = np.argsort(idx, kind="stable")
    srt = idx[by_row]
    pieces, offset = [], 0
    for batch in batches if key_cols else ():
        n = batch.num_rows
        lo, hi = np.searchsorted(srt, [offset, offset + n])
        if hi > lo:
            pieces.append(pa.Table.from_batches([batch.select(key_cols).take(pa.array(srt[lo:hi] - offset))]))
        offset += n
    cols = {}
    if key_cols:
        keys = pa.concat_tables(pieces) if pieces else None
        back = np.empty_like(by_row)
        back[by_row] = np.arange(len(by_row))  # input order -> score order
        for c in key_cols:
            cols[c] = keys.column(c).take(pa.array(back)) if keys is not None else pa.array([], pa.string())
    S = cons.sus
    at = np.searchsorted(S["idx"], idx) if S is not None else np.zeros(0, np.int64)
    cols["row"] = pa.array(S["line"][at] if S is not None else [], pa.int64())
    cols["score"] = pa.array([round(float(v), 3) for v in (S["score"][at] if S is not None else [])], pa.float64())
    why = [cons._why(*v) for v in zip(*(S[k][at] for k in ("lm_angle", "lm_ratio", "view_angle", "jump")))] if S else []
    cols["reason"] = pa.array(why, pa.string())
    return pa.table(cols)


def _key_batches(cons, reread, key_cols):
    """Batches of (at least) the key columns, in input order, for :meth:`ConsistencyAudit.describe_rows`.

    A Parquet file read under its own column names is read again for the key
    columns only (Parquet rows are never set aside, so the row indices agree);
    anything else is read again whole with ``reread()``.
    """
    import pyarrow.parquet as pq  # lazy: only --consistency reads the keys again

    src = cons.src
    if src.kind == "parquet" and key_cols:
        names = set(pq.ParquetFile(src.path).schema_arrow.names)
        if set(key_cols) <= names and names == set(src.columns) - {"__line__"}:
            return pq.ParquetFile(src.path).iter_batches(65_536, columns=key_cols)
    return reread()


def canonical_labels(system, cols, eff, res) -> np.ndarray:
    """The audited labels as canonical matrices ``(n, 3, 3)``; NaN for rows that are not finite rotations."""
    values = np.stack(cols, axis=-1)
    bad = res["non_finite"] | res.get("not_rotation", False)
    values = np.where(np.asarray(bad)[:, None], 0.0, values)
    A = system.to_canonical(system.from_angles(values) if eff == "angles" else values.reshape(-1, 3, 3))
    A[np.asarray(bad)] = np.nan
    return A


def _codes(col, table: dict) -> np.ndarray:
    """Global integer codes of an Arrow column's values (strings or ints), via dictionary encoding."""

    import pyarrow.compute as pc  # lazy: 0.1-0.2 s to import, only --consistency needs it

    if pa.types.is_integer(col.type):
        return arrow_to_numpy(col).astype(np.int64)
    enc = pc.dictionary_encode(col.cast(pa.string()))
    values = enc.dictionary.to_pylist()
    remap = np.array([table.setdefault(v, len(table)) for v in values] + [-1], dtype=np.int64)
    idx = enc.indices.fill_null(len(values)).to_numpy(zero_copy_only=False)
    return remap[idx]
