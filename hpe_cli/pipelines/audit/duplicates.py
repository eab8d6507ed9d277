"""Duplicate rows of an audit: one 64-bit hash a row (label bits + key columns), found after the stream.

Equal rows get equal hashes: label values enter as their exact bits (-0.0 = 0.0, every NaN one NaN), text
columns as a 64-bit hash of their bytes taken from the Arrow buffers (no Python strings). The hashes are the
audit's only per-row state: 16 bytes a row (kept in input order and split by value half, :class:`Duplicates`;
the sort at the end of the run needs no other copy).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from ...io import key_hash
from ...io.table_source import plain_numpy

#: columns that identify a sample, used (when present) in the ``duplicates`` key
ID_COLUMNS = (
    "file",
    "image",
    "image_id",
    "id",
    "path",
    "person_id",
    "face_id",
    "frame",
    "camera",
    "bbox_x",
    "bbox_y",
    "bbox_w",
    "bbox_h",
)
_SEED = 0x9E3779B97F4A7C15
_ROW_MULT = np.uint64(0x9FB21C651E98DF25)  # odd multiplier of the per-word step of the row hash
#: integers cast to float64 exactly (Arrow's safe cast refuses the others; :func:`key_words` lets it)
_EXACT_INT = 2**53


# ------------------------------------------------------------------------------------------------- hashing
def float_words(values):
    """float64 values as exact uint64 words: -0.0 -> 0.0 and every NaN -> one NaN, so equal values match."""
    v = np.asarray(values, dtype=np.float64)
    w = np.ascontiguousarray(v + 0.0)  # a new array: -0.0 + 0.0 is 0.0
    if len(w) and np.isnan(w.max()):  # max propagates NaN: one pass, no mask in the usual batch
        w[np.isnan(w)] = np.nan
    return w.view(np.uint64)


def string_hashes(col) -> np.ndarray:
    """One 64-bit hash per value of an Arrow string or binary array, off its buffers (no Python strings; nulls
    share one word): :func:`hpe_cli.io.key_hash.string_hashes`, the hash evaluate's key join uses."""
    return key_hash.string_hashes(col, stems=False)[0]


def key_words(batch, name):
    """Column ``name`` of ``batch`` as one uint64 word a row: numbers as their float64 bits, the rest hashed."""

    col = batch.column(batch.schema.get_field_index(name))
    t = col.type
    if col.null_count == 0 and str(t) in ("double", "int64", "int32"):
        v = plain_numpy(col)  # a view of the buffer (Arrow's to_numpy imports pandas)
        if v.dtype.kind == "f":
            return float_words(v)
        if not len(v) or (v.min() >= -_EXACT_INT and v.max() <= _EXACT_INT):  # what Arrow's cast accepts
            return v.astype(np.float64).view(np.uint64)  # Arrow's cast, exact here (never -0.0 or NaN)
    is_text = pa.types.is_string(t) or pa.types.is_large_string(t) or pa.types.is_binary(t)
    if is_text or pa.types.is_large_binary(t):
        return string_hashes(col)
    import pyarrow.compute as pc  # lazy: 0.1-0.2 s to import, not needed for text, float64 and int64 columns

    if pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t):
        return float_words(pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False))
    col = pc.cast(col, pa.string())
    return string_hashes(col)


def key_hashes(label_cols, batch, key_cols) -> np.ndarray:
    """One 64-bit hash per row of (label values, key columns): equal rows get equal hashes.

    Label values enter as their exact bits (-0.0 = 0.0, all NaNs equal); text
    columns as a 64-bit hash of their bytes.
    """
    n = len(label_cols[0])
    h = np.full(n, _SEED, dtype=np.uint64)
    t = np.empty(n, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for k in range(len(label_cols) + len(key_cols)):
            w = float_words(label_cols[k]) if k < len(label_cols) else key_words(batch, key_cols[k - len(label_cols)])
            np.bitwise_xor(h, w, out=h)  # h = ((h ^ w) * M) ^ (that >> 32): a bijection of h for each w
            np.multiply(h, _ROW_MULT, out=h)
            np.right_shift(h, np.uint64(32), out=t)
            np.bitwise_xor(h, t, out=h)
        for shift, mult in ((30, 0xBF58476D1CE4E5B9), (27, 0x94D049BB133111EB), (31, None)):  # SplitMix64 finaliser
            np.right_shift(h, np.uint64(shift), out=t)
            np.bitwise_xor(h, t, out=h)
            if mult is not None:
                np.multiply(h, np.uint64(mult), out=h)
    return h


def split_halves(h):
    """``(h[h < 2**63], h[h >= 2**63])``: a batch's hashes by value half, in input order (for :class:`Duplicates`)."""
    low = h.view(np.int64) >= 0  # top bit clear; np.compress is about twice as fast as a boolean index here
    return np.compress(low, h), np.compress(~low, h)


class Duplicates:
    """Duplicates from one 64-bit hash per row (16 bytes a row; the only per-row state of an audit).

    With the row count known (Parquet), the hashes are copied as batches come in into one array in input
    order and, split by value half (:func:`split_halves`), into a second one filled from both ends; the
    end of the run then sorts the two halves in place, on two threads, with no copy and no scan.
    """

    def __init__(self, rows: int | None = None):
        self.buf = np.empty(rows, dtype=np.uint64) if rows else None
        self.halves = np.empty(rows, dtype=np.uint64) if rows else None
        self.n_low = self.n_high = 0
        self.parts = []
        self.batch_sizes = []
        self.lines = []  # (row index, line) where the line numbering jumps (CSV rejects, blank lines)
        self.n = 0
        self._prev_line = None

    def add(self, h, lines, halves=None):
        """Add one batch's hashes ``h`` (and their :func:`split_halves`, if computed) and file lines."""
        if self.buf is not None and self.n + len(h) <= len(self.buf) and not self.parts:
            self.buf[self.n : self.n + len(h)] = h
            self._add_halves(h, halves)
        else:
            if self.buf is not None:  # more rows than announced: keep what was copied as the first part
                self.parts.append(self.buf[: self.n])
                self.buf = self.halves = None
            self.parts.append(h)
        self.batch_sizes.append(len(h))
        if len(lines):
            jumps = np.flatnonzero(np.diff(lines) != 1) + 1
            if self._prev_line is None or lines[0] != self._prev_line + 1:
                self.lines.append((self.n, int(lines[0])))
            for j in jumps:
                self.lines.append((self.n + int(j), int(lines[j])))
            self._prev_line = int(lines[-1])
        self.n += len(h)

    def _add_halves(self, h, halves) -> None:
        low, high = split_halves(h) if halves is None else halves
        end = len(self.halves) - self.n_high
        self.halves[self.n_low : self.n_low + len(low)] = low
        self.halves[end - len(high) : end] = high
        self.n_low += len(low)
        self.n_high += len(high)

    def finish(self, threads: int = 1):
        """Compute the duplicate rows; returns their count.

        The hashes equal to another are found by sorting, each value range on a
        thread of its own (numpy releases the GIL), so the result does not
        depend on ``threads``.
        """
        halves = None
        if self.buf is not None:
            H = self.buf[: self.n]
            end = len(self.halves)
            halves = (self.halves[: self.n_low], self.halves[end - self.n_high : end])
        else:
            H = np.concatenate(self.parts) if self.parts else np.zeros(0, dtype=np.uint64)
        self.parts, self.buf, self.halves = [], None, None
        self.H = H
        self.dup_idx = np.zeros(0, dtype=np.int64)
        self.first_idx = np.zeros(0, dtype=np.int64)
        if len(H) < 2:
            return 0
        dupvals = repeated_values(H, threads) if halves is None else repeated_in_halves(halves, threads)
        if not len(dupvals):
            return 0
        idx = []
        for lo in range(0, len(H), 1 << 20):
            chunk = H[lo : lo + (1 << 20)]
            pos = np.minimum(np.searchsorted(dupvals, chunk), len(dupvals) - 1)
            idx.append(np.flatnonzero(dupvals[pos] == chunk) + lo)
        idx = np.concatenate(idx)
        vals = H[idx]
        uniq, first = np.unique(vals, return_index=True)
        first_of = idx[first[np.searchsorted(uniq, vals)]]
        is_dup = first_of != idx
        self.dup_idx = idx[is_dup]
        self.first_idx = first_of[is_dup]
        return int(is_dup.sum())

    def line_of(self, i):
        i = np.asarray(i, dtype=np.int64)
        if not self.lines:
            return i + 2
        starts = np.array([s for s, _ in self.lines], dtype=np.int64)
        first = np.array([ln for _, ln in self.lines], dtype=np.int64)
        k = np.searchsorted(starts, i, side="right") - 1
        return first[k] + (i - starts[k])

    def mask(self, lo, hi):
        a, b = np.searchsorted(self.dup_idx, [lo, hi])
        m = np.zeros(hi - lo, dtype=bool)
        m[self.dup_idx[a:b] - lo] = True
        return m


def _repeats(S) -> np.ndarray:
    """The values that occur more than once in the sorted array ``S``, sorted."""
    same = S[1:] == S[:-1]
    return np.unique(S[1:][same]) if same.any() else S[:0]


def repeated_in_halves(halves, threads: int = 1) -> np.ndarray:
    """:func:`repeated_values` of the union of ``halves`` (the values below 2**63, then the others), sorting
    each in place (on two threads when ``threads > 1``)."""

    def one(S):
        S.sort()
        return _repeats(S)

    if threads > 1 and min(len(x) for x in halves) >= 1 << 16:
        from concurrent.futures import ThreadPoolExecutor  # lazy: start-up

        with ThreadPoolExecutor(2) as pool:
            return np.concatenate(list(pool.map(one, halves)))
    return np.concatenate([one(x) for x in halves])


def repeated_values(H, threads: int = 1) -> np.ndarray:
    """The values that occur more than once in the uint64 array ``H``, sorted (whatever ``threads``).

    With ``threads > 1`` the values are split by their top bits into ``threads`` ranges, each selected
    and sorted on its own thread (the hashes are uniform, so the ranges hold about as many).
    """
    parts = max(1, min(int(threads), 16)) if len(H) >= 1 << 20 else 1

    def one(k):
        if parts == 1:
            S = np.sort(H)
        else:
            lo, hi = np.uint64((k << 64) // parts), np.uint64(((k + 1) << 64) // parts - 1)
            S = H[H <= hi] if k == 0 else (H[H >= lo] if k == parts - 1 else H[(H >= lo) & (H <= hi)])
            S.sort()
        return _repeats(S)

    if parts == 1:
        return one(0)
    from concurrent.futures import ThreadPoolExecutor  # lazy: start-up

    with ThreadPoolExecutor(parts) as pool:
        return np.concatenate(list(pool.map(one, range(parts))))


def unpack_rows(flag_bits, batch_sizes, idx) -> np.ndarray:
    """The stored flag bit of every global row index in ``idx`` (sorted)."""
    out = np.zeros(len(idx), dtype=bool)
    starts = np.concatenate([[0], np.cumsum(batch_sizes)]).astype(np.int64)
    k = np.searchsorted(starts, idx, side="right") - 1
    for b in np.unique(k):
        sel = k == b
        bits = np.unpackbits(flag_bits[b], count=int(batch_sizes[b])).astype(bool)
        out[sel] = bits[idx[sel] - starts[b]]
    return out
