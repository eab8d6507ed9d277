"""The notes, statistics and suspects list of ``hpe audit --consistency`` (:mod:`hpe_cli.pipelines.consistency`)."""

from __future__ import annotations

import numpy as np


def _reason_codes(lm, view, time) -> tuple:
    """``(codes, texts)``: ``texts[codes[i]]`` is ``"not checked: landmarks: ...; views: ...; time: ..."``
    for row ``i``; each distinct combination is formatted once."""
    import pandas as pd

    if len(lm) == 0:
        return np.zeros(0, np.int32), []
    codes, uniq = zip(*(pd.factorize(pd.Series(a, dtype=object)) for a in (lm, view, time)))
    sizes = [len(u) + 1 for u in uniq]
    key = (np.asarray(codes[0], np.int64) * sizes[1] + codes[1]) * sizes[2] + codes[2]
    combos, inverse = np.unique(key, return_inverse=True)
    text = []
    for k in combos:
        a, rest = divmod(int(k), sizes[1] * sizes[2])
        b, c = divmod(rest, sizes[2])
        text.append(f"not checked: landmarks: {uniq[0][a]}; views: {uniq[1][b]}; time: {uniq[2][c]}")
    return inverse.reshape(-1).astype(np.int32), text


class _Notes:
    """``consistency_note`` of every row without an array of N strings: the suspects' reasons (sparse) and a
    code per not-checked row into the few distinct not-checked texts; ``""`` for the other rows."""

    def __init__(self, n, sus_idx, sus_txt, un_idx, un_codes, un_texts):
        self.n = n
        self.sus_idx, self.sus_txt = np.asarray(sus_idx, np.int64), np.array(sus_txt + [""], dtype=object)
        self.un_idx, self.un_codes = np.asarray(un_idx, np.int64), np.asarray(un_codes, np.int32)
        self.un_texts = np.array(list(un_texts) + [""], dtype=object)

    def slice(self, offset: int, n: int) -> np.ndarray:
        out = np.full(n, "", dtype=object)
        lo, hi = np.searchsorted(self.un_idx, [offset, offset + n])
        out[self.un_idx[lo:hi] - offset] = self.un_texts[self.un_codes[lo:hi]]
        lo, hi = np.searchsorted(self.sus_idx, [offset, offset + n])
        out[self.sus_idx[lo:hi] - offset] = self.sus_txt[lo:hi]
        return out

    def __getitem__(self, i) -> str:
        return str(self.slice(int(i), 1)[0])


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
