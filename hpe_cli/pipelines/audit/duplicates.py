"""Duplicate rows of an audit: one 64-bit hash a row (label bits + key columns), found after the stream.

Equal rows get equal hashes: label values enter as their exact bits (-0.0 = 0.0, every NaN one NaN), text
columns as a 64-bit hash of their bytes taken from the Arrow buffers (no Python strings). The hashes are the
audit's only per-row state: 8 bytes a row while the batches stream (written in input order by the threads
that check them, :class:`Duplicates`), 16 at the end, when each value half is selected and sorted.
"""

from __future__ import annotations

import threading

import numpy as np
import pyarrow as pa

from ...io import key_hash
from ...io.table_source import plain_numpy
from ...native import kernels
from ..heap import small_page_array

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


def key_hashes(label_cols, batch, key_cols, out=None) -> np.ndarray:
    """One 64-bit hash per row of (label values, key columns): equal rows get equal hashes.

    Label values enter as their exact bits (-0.0 = 0.0, all NaNs equal); text
    columns as a 64-bit hash of their bytes. ``out``: a uint64 array of the rows' length to write them to.
    """
    n = len(label_cols[0])
    h = np.empty(n, dtype=np.uint64) if out is None else out
    h.fill(_SEED)
    k = kernels()
    if k is not None:  # the same hashes, one C loop a column (csrc/kernels/hashes.c); the numpy twin below
        for c in range(len(label_cols) + len(key_cols)):
            if c < len(label_cols):
                k.row_hash_add(h, np.ascontiguousarray(label_cols[c], dtype=np.float64), True)
            else:
                k.row_hash_add(h, np.ascontiguousarray(key_words(batch, key_cols[c - len(label_cols)])), False)
        k.mix(h)
        return h
    t = np.empty(n, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for k in range(len(label_cols) + len(key_cols)):
            w = float_words(label_cols[k]) if k < len(label_cols) else key_words(batch, key_cols[k - len(label_cols)])
            np.bitwise_xor(h, w, out=h)  # h = ((h ^ w) * M) ^ (that >> 32): a bijection of h for each w
            np.multiply(h, _ROW_MULT, out=h)
            np.right_shift(h, np.uint64(32), out=t)
            np.bitwise_xor(h, t, out=h)
    return key_hash.mix(h, t)  # SplitMix64's finaliser


class Duplicates:
    """Duplicates from one 64-bit hash per row (16 bytes a row; the only per-row state of an audit).

    With the row count known (Parquet), the thread that checks a batch writes its hashes straight into one
    array in input order (:meth:`slot`: the batch's rows by their offset) and copies them, split by value
    half, into a second array filled from both ends (:meth:`file`); the end of the run sorts the two halves in
    place, on two threads, with no copy. Without the row count the hashes are kept batch by batch and put end to
    end at the end, each value half then selected and sorted on a thread of its own.
    """

    def __init__(self, rows: int | None = None):
        self.buf = small_page_array(rows, np.uint64) if rows else None  # 4 KB pages: pipelines.heap
        self.halves = small_page_array(rows, np.uint64) if rows else None
        self.n_low = self.n_high = 0  # values below 2**63 at the front of halves, the others at its back
        self._lock = threading.Lock()
        self.parts = []  # every batch's hashes, in input order (views of buf where they were written there)
        self.batch_sizes = []
        self.lines = []  # (row index, line) where the line numbering jumps (CSV rejects, blank lines)
        self.n = 0
        self._prev_line = None

    def slot(self, offset: int, n: int):
        """Where the hashes of the ``n`` rows starting at row ``offset`` go: a view of the in-order array, or None
        (no row count, or more rows than announced). Any thread may call it."""
        if self.buf is None or offset + n > len(self.buf):
            return None
        return self.buf[offset : offset + n]

    def file(self, h) -> None:
        """Copy a batch's hashes (its filled :meth:`slot`) into the value halves. Any thread may call it: the order
        of the batches in a half does not matter, it is sorted."""
        k = kernels()
        if k is not None:  # one C loop (csrc/kernels/hashes.c); the numpy twin below
            low, high = np.empty(len(h), dtype=np.uint64), np.empty(len(h), dtype=np.uint64)
            n_low = k.split_top_bit(h, low, high)
            low, high = low[:n_low], high[: len(h) - n_low]
        else:
            top = h.view(np.int64) < 0
            low, high = h[~top], h[top]
        with self._lock:
            at, self.n_low = self.n_low, self.n_low + len(low)
            end, self.n_high = len(self.halves) - self.n_high, self.n_high + len(high)
        self.halves[at : at + len(low)] = low
        self.halves[end - len(high) : end] = high

    def add(self, h, lines):
        """Add one batch's hashes ``h`` (its :meth:`slot` once filled, or an array of its own) and file lines
        (increasing), in input order."""
        self.parts.append(h)
        self.batch_sizes.append(len(h))
        if len(lines):
            if self._prev_line is None or lines[0] != self._prev_line + 1:
                self.lines.append((self.n, int(lines[0])))
            if lines[-1] - lines[0] != len(lines) - 1:  # increasing lines with that span are consecutive
                for j in np.flatnonzero(np.diff(lines) != 1) + 1:
                    self.lines.append((self.n + int(j), int(lines[j])))
            self._prev_line = int(lines[-1])
        self.n += len(h)

    def _in_buf(self) -> bool:
        """Every batch was written to its :meth:`slot` and filed (the value halves hold every hash)."""
        buf = self.buf
        return buf is not None and self.n_low + self.n_high == self.n and self.n <= len(buf)

    def finish(self, threads: int = 1):
        """Compute the duplicate rows; returns their count.

        The hashes equal to another are found by sorting, each value half on a
        thread of its own (numpy releases the GIL), so the result does not
        depend on ``threads``.
        """
        halves = None
        if self._in_buf():  # every hash in input order in buf, and split by value in halves
            H, end = self.buf[: self.n], len(self.halves)
            halves = (self.halves[: self.n_low], self.halves[end - self.n_high : end])
        else:
            H = np.concatenate(self.parts) if self.parts else np.zeros(0, dtype=np.uint64)
        self.parts, self.buf, self.halves = [], None, None
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


def _half(H, low: bool, size: int) -> np.ndarray:
    """The ``size`` values of ``H`` below 2**63 (``low``) or the others, in order, selected 1M values at a time
    (``np.compress`` of the whole would hold an index array of the selected values beside them)."""
    S = np.empty(size, dtype=np.uint64)
    k = 0
    for lo in range(0, len(H), 1 << 20):
        chunk = H[lo : lo + (1 << 20)]
        m = chunk.view(np.int64) >= 0 if low else chunk.view(np.int64) < 0
        c = int(np.count_nonzero(m))
        np.compress(m, chunk, out=S[k : k + c])
        k += c
    return S


def _repeats_of_halves(half, parallel: bool) -> np.ndarray:
    """The repeated values of the two value halves ``half(True)`` (below 2**63) and ``half(False)``, each made and
    sorted in place on a thread of its own when ``parallel``, sorted (the same whatever the threads)."""

    def one(low: bool):
        S = half(low)
        S.sort()
        return _repeats(S)

    if parallel:
        from concurrent.futures import ThreadPoolExecutor  # lazy: start-up

        with ThreadPoolExecutor(2) as pool:
            return np.concatenate(list(pool.map(one, (True, False))))
    return np.concatenate([one(True), one(False)])


def repeated_in_halves(halves, threads: int = 1) -> np.ndarray:
    """:func:`repeated_values` of the union of ``halves`` (the values below 2**63, then the others), sorting
    each in place (on two threads when ``threads > 1``)."""
    parallel = threads > 1 and min(len(x) for x in halves) >= 1 << 16
    return _repeats_of_halves(lambda low: halves[0 if low else 1], parallel)


def repeated_values(H, threads: int = 1) -> np.ndarray:
    """The values that occur more than once in the uint64 array ``H``, sorted (whatever ``threads``).

    The values below 2**63 and the others are each selected into an array of their own and sorted in place, on
    two threads when ``threads > 1`` (the hashes are uniform, so the halves hold about as many).
    """
    n_low = int(np.count_nonzero(H.view(np.int64) >= 0))
    return _repeats_of_halves(
        lambda low: _half(H, low, n_low if low else len(H) - n_low), threads > 1 and len(H) >= 1 << 17
    )


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
