"""Duplicate rows of an audit: one 64-bit hash a row (label bits + key columns), found after the stream.

Equal rows get equal hashes: label values enter as their exact bits (-0.0 = 0.0, every NaN one NaN), text
columns as a 64-bit hash of their bytes taken from the Arrow buffers (no Python strings). The hashes are the
audit's only per-row state, about 16 bytes a row: written in input order by the threads that check the batches,
and filed by value (:class:`HashBuckets` or two value halves, :class:`Duplicates`); the repeated values are found
at the end of the stream, by bucket or by value half on two threads.
"""

from __future__ import annotations

import threading

import numpy as np
import pyarrow as pa

from ...io import key_hash
from ...io.table_source import plain_numpy
from ...native import kernels
from ..heap import prefault, small_page_array

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


class HashBuckets:
    """The hashes of a run by their top 10 bits, as the batches are checked (the compiled kernels only).

    Bucket ``b`` owns ``cap`` slots of one array, about 1.1 times the rows at 10M (the expected count and ten
    standard deviations more); the threads that file batches reserve their runs with atomic additions
    (``bucket_file``, csrc/kernels/repeats.c). :meth:`repeated` finds the repeated values of the two value halves
    (512 buckets each, a thread each when ``threads > 1``) bucket by bucket in cache (``bucket_repeats``), or,
    when a bucket was full (many equal rows), with :func:`repeated_in_place` of a copy of the hashes in input
    order: the same values either way, sorted.
    """

    BITS = 10
    #: below this many rows the value halves (one array, two sorts) cost less than the buckets' slack
    MIN_ROWS = 1 << 17

    def __init__(self, rows: int):
        per = rows / (1 << self.BITS)
        self.cap = int(np.ceil(per + 10.0 * np.sqrt(per))) + 64
        self.arr = small_page_array(self.cap << self.BITS, np.uint64)
        self.cursors = np.zeros(1 << self.BITS, dtype=np.int64)
        self.full = False
        self._k = kernels()  # the module the run started with (HPE_KERNELS is read on each kernels() call)

    def file(self, h) -> None:
        """Add a batch's hashes (any thread, any order)."""
        if not self._k.bucket_file(h, self.arr, self.cursors, self.cap):
            self.full = True

    def filed(self) -> int:
        """How many hashes were filed."""
        return int(self.cursors.sum())

    def repeated(self, H, threads: int = 1) -> np.ndarray:
        """The repeated values of the filed hashes ``H`` (all of them, in input order), sorted; the buckets are
        scratch."""
        k = self._k
        if self.full:  # a bucket overflowed: from H
            S = self.arr[: len(H)]
            S[:] = H
            return repeated_in_place(S).copy()
        half = 1 << (self.BITS - 1)

        def one(lo: int):
            return np.frombuffer(k.bucket_repeats(self.arr, self.cursors, self.cap, lo, lo + half), dtype=np.uint64)

        if threads > 1:
            from concurrent.futures import ThreadPoolExecutor  # lazy: start-up

            with ThreadPoolExecutor(2) as pool:
                return np.concatenate(list(pool.map(one, (0, half))))
        return np.concatenate([one(0), one(half)])


class Duplicates:
    """Duplicates from one 64-bit hash per row (16 bytes a row; the only per-row state of an audit).

    With the row count known (Parquet), the thread that checks a batch writes its hashes straight into one
    array in input order (:meth:`slot`: the batch's rows by their offset) and copies them (:meth:`file`) into
    a second array: with the compiled kernels, into 1024 buckets by their top 10 bits (:class:`HashBuckets`),
    whose repeats the end of the run finds bucket by bucket in cache on two threads; else split by value half,
    filled from both ends, each half sorted in place at the end on a thread of its own. Without the row count
    the hashes are kept batch by batch and put end to end at the end, each value half then selected and searched
    on a thread of its own.
    """

    def __init__(self, rows: int | None = None):
        self.buf = small_page_array(rows, np.uint64) if rows else None  # 4 KB pages: pipelines.heap
        self.buckets = HashBuckets(rows) if rows and rows >= HashBuckets.MIN_ROWS and kernels() else None
        self.halves = small_page_array(rows, np.uint64) if rows and self.buckets is None else None
        prefault(*(a for a in (self.buf, self.halves, self.buckets and self.buckets.arr) if a is not None))
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
        """Copy a batch's hashes (its filled :meth:`slot`) into the buckets or the value halves. Any thread may call
        it: the order of the batches in a bucket or a half does not matter."""
        if self.buckets is not None:
            self.buckets.file(h)
            return
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
        """Every batch was written to its :meth:`slot` and filed (the buckets or value halves hold every hash)."""
        buf = self.buf
        filed = self.buckets.filed() if self.buckets is not None else self.n_low + self.n_high
        return buf is not None and filed == self.n and self.n <= len(buf)

    def _repeated(self, threads: int) -> np.ndarray:
        """The repeated hashes, once every batch is in :attr:`buf` and filed (:meth:`_in_buf`)."""
        if self.buckets is not None:
            return self.buckets.repeated(self.buf[: self.n], threads)
        end = len(self.halves)
        return repeated_in_halves((self.halves[: self.n_low], self.halves[end - self.n_high : end]), threads)

    def finish(self, threads: int = 1):
        """Compute the duplicate rows; returns their count.

        The hashes equal to another are found by value half or bucket range, each on a thread of its own (numpy
        and the kernels release the GIL), and put in increasing order, so the result does not depend on
        ``threads``.
        """
        self.dup_idx = np.zeros(0, dtype=np.int64)
        self.first_idx = np.zeros(0, dtype=np.int64)
        if self._in_buf():  # every hash in input order in buf, and filed by value
            H = self.buf[: self.n]
            dupvals = self._repeated(threads) if len(H) >= 2 else H[:0]
        else:
            H = np.concatenate(self.parts) if self.parts else np.zeros(0, dtype=np.uint64)
            dupvals = repeated_values(H, threads) if len(H) >= 2 else H[:0]
        self.parts, self.buf, self.halves, self.buckets = [], None, None, None
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


def repeated_in_place(S) -> np.ndarray:
    """The values that occur more than once in the uint64 array ``S``, once each, sorted; ``S`` is scratch (left
    reordered) and the result may be a view of it.

    The kernel (``repeated_values``, csrc/kernels/repeats.c: a radix partition in place, then a hash set per
    cache-sized bucket; 0.75x the CPU of the sort at 5M values) where built, else its numpy twin: sort in place and
    take the values equal to their successor. The same values either way.
    """
    k = kernels()
    if k is not None:
        return S[: k.repeated_values(S)]
    S.sort()
    return _repeats(S)


def _repeats_of_halves(half, parallel: bool) -> np.ndarray:
    """The repeated values of the two value halves ``half(True)`` (below 2**63) and ``half(False)``, each made and
    searched in place (:func:`repeated_in_place`) on a thread of its own when ``parallel``, sorted (the same
    whatever the threads)."""

    def one(low: bool):
        return repeated_in_place(half(low))

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
