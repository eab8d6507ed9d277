"""The notes, statistics and suspects list of ``hpe audit --consistency`` (:mod:`hpe_cli.pipelines.consistency`)."""

from __future__ import annotations

import numpy as np


def _r(v):
    return None if not np.isfinite(v) else round(float(v), 3)


def _stats(x) -> dict:
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return {"n": 0}
    q = np.percentile(x, [50, 90, 99])
    return {"n": int(x.size), "median": _r(q[0]), "p90": _r(q[1]), "p99": _r(q[2]), "max": _r(x.max())}


def suspects_table(rows: list, key_cols: list):
    """The suspects key list: key columns, ``row``, ``score`` and ``reason`` (what ``--exclude`` reads)."""
    import pyarrow as pa

    cols = {c: [r.get(c) for r in rows] for c in key_cols}
    cols["row"] = [r["row"] for r in rows]
    cols["score"] = [r["score"] for r in rows]
    cols["reason"] = [r["reason"] for r in rows]
    return pa.table(cols)


def _key_batches(cons, reread, key_cols):
    """Batches of (at least) the key columns, in input order, for :meth:`ConsistencyAudit.describe_rows`.

    A Parquet file read under its own column names is read again for the key
    columns only (Parquet rows are never set aside, so the row indices agree);
    anything else is read again whole with ``reread()``.
    """
    src = cons.src
    if src.kind == "parquet" and key_cols:
        import pyarrow.parquet as pq

        names = set(pq.ParquetFile(src.path).schema_arrow.names)
        if set(key_cols) <= names and names == set(src.columns) - {"__line__"}:
            return pq.ParquetFile(src.path).iter_batches(65_536, columns=key_cols)
    return reread()
