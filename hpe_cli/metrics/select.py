"""Exact percentiles of float32 values read piece by piece: memory flat in the number of values.

``np.percentile`` needs the whole array (and partitions a copy of it). Its linear method reads only two order
statistics per percentile, the ``floor`` and ``ceil`` of a virtual index, and interpolates between them. Here those
order statistics are found by a two-level radix select over the values' bits: one pass counts the top 16 bits of
each value's order-preserving 32-bit key, a second pass counts the low 16 bits inside the few top buckets that hold
a wanted rank, which gives each wanted value exactly. The first pass can be taken while the values are made
(:func:`top_counts` of each piece, summed: the counts of the float32 bit patterns' top halves, which the keys only
reorder), so that only the second remains at the end. The interpolation is then numpy's own (its private
``_lerp`` and index helpers, so the numbers are ``np.percentile``'s to the bit; tested against it), with
``np.percentile`` on the whole array as the fallback where those helpers are missing or a NaN or an infinity is
present.
"""

from __future__ import annotations

import numpy as np

_TOP = 1 << 16


def _keys(v: np.ndarray) -> np.ndarray:
    """Order-preserving uint32 keys of float32 values (negative values flipped, positive ones offset)."""
    u = np.ascontiguousarray(v, dtype=np.float32).view(np.uint32)
    neg = (u >> np.uint32(31)).astype(bool)
    return np.where(neg, ~u, u | np.uint32(0x80000000))


def _values(keys: np.ndarray) -> np.ndarray:
    """The float32 values of :func:`_keys` keys."""
    k = np.asarray(keys, dtype=np.uint32)
    pos = (k >> np.uint32(31)).astype(bool)
    return np.where(pos, k & np.uint32(0x7FFFFFFF), ~k).astype(np.uint32).view(np.float32)


def _ranks(n: int, q: np.ndarray):
    """``(previous, next, gamma)`` of numpy's linear method for ``n`` values and quantiles ``q`` (fractions), from
    numpy's own helpers (None when this numpy has other ones)."""
    try:
        from numpy.lib import _function_base_impl as fb  # lazy: numpy's private helpers, checked by a test

        method = fb._QuantileMethods["linear"]
        virtual = np.asanyarray(method["get_virtual_index"](n, q))
        prev, nxt = fb._get_indexes(np.empty(n, dtype=np.float32), virtual, n)
        gamma = fb._get_gamma(virtual, prev, method)
        prev, nxt = (np.where(np.asarray(x) < 0, n - 1, np.asarray(x)).astype(np.int64) for x in (prev, nxt))
        return prev, nxt, gamma, fb._lerp  # (-1 is numpy's "the last value")
    except (ImportError, AttributeError, KeyError, TypeError):
        return None


def top_counts(v: np.ndarray) -> np.ndarray:
    """The first pass of :func:`percentiles_of_pieces` over one piece: how many of the float32 values ``v`` have
    each top 16 bits (of their bit patterns), int64 (65536,). The counts of several pieces add up."""
    u = np.ascontiguousarray(v, dtype=np.float32).view(np.uint32)
    return np.bincount(u >> np.uint32(16), minlength=_TOP)


#: the top 16 bits of an order-preserving key (:func:`_keys`) for each top 16 bits of a float32 bit pattern
_KEY_TOP = np.where(np.arange(_TOP) >= 1 << 15, ~np.arange(_TOP) & 0xFFFF, np.arange(_TOP) | 1 << 15)
#: bit patterns' top 16 bits of infinities and NaNs (the exponent's 8 bits all set)
_NOT_FINITE = (np.arange(_TOP) & 0x7F80) == 0x7F80


def percentiles_of_pieces(pieces, n: int, q, top: np.ndarray | None = None, threads: int = 1) -> np.ndarray | None:
    """``np.percentile(all values, q)`` of ``n`` float32 values that ``pieces()`` yields piece by piece.

    Parameters
    ----------
    pieces : callable or sequence of callables
        Returns a fresh iterable of float32 arrays (the values in any order), called once or twice. A sequence:
        each callable yields its own part of the values (together all of them); the parts are read side by side
        on up to ``threads`` threads.
    n : int
        The number of values (> 0).
    q : sequence of float
        Percentiles in [0, 100].
    top : ndarray (65536,) of int, optional
        The sum of :func:`top_counts` over the same values, taken while they were made (the first pass: the
        values are then read once here).
    threads : int, optional
        Threads that count the parts of ``pieces`` (the counts are integers: the same sums in any order).

    Returns
    -------
    ndarray (len(q),) or None
        The percentiles, equal to ``np.percentile``'s on the concatenated values; None when a value is NaN or
        infinite, or this numpy lacks the helpers (the caller then takes ``np.percentile`` on the whole array).
    """
    got = _ranks(n, np.true_divide(np.asarray(q, dtype=np.float64), 100))
    if got is None or n <= 0:
        return None
    parts = list(pieces) if isinstance(pieces, (list, tuple)) else [pieces]
    prev, nxt, gamma, lerp = got
    ranks = np.unique(np.concatenate([prev, nxt]))
    if top is None:
        top = np.zeros(_TOP, dtype=np.int64)
        for part in parts:
            for v in part():
                top += top_counts(v)
    if top[_NOT_FINITE].any():
        return None
    keyed = np.zeros(_TOP, dtype=np.int64)
    keyed[_KEY_TOP] = top  # counts per top 16 bits of the keys, in the values' order
    cum = np.cumsum(keyed)
    if cum[-1] != n:
        raise ValueError(f"expected {n} values, got {int(cum[-1])}")
    bucket = np.searchsorted(cum, ranks, side="right")  # the top bucket of each wanted rank
    low_rank = ranks - np.where(bucket > 0, cum[np.maximum(bucket - 1, 0)], 0)
    wanted = np.unique(bucket)
    slot = np.full(_TOP, -1, dtype=np.int32)  # per top 16 bits of a bit pattern: its wanted bucket, or -1
    hit = np.isin(_KEY_TOP, wanted)
    slot[hit] = np.searchsorted(wanted, _KEY_TOP[hit])
    low = _second_pass(parts, slot, len(wanted), threads)
    key_of = {}
    for r, b, lr in zip(ranks, bucket, low_rank):
        row = np.cumsum(low[int(np.searchsorted(wanted, b))])
        key_of[int(r)] = (int(b) << 16) | int(np.searchsorted(row, lr, side="right"))
    order = _values(np.array([key_of[int(r)] for r in ranks], dtype=np.uint32))
    at = dict(zip((int(r) for r in ranks), order))
    a = np.array([at[int(r)] for r in prev], dtype=np.float32)
    b = np.array([at[int(r)] for r in nxt], dtype=np.float32)
    return np.asarray(lerp(a, b, gamma))


def _low_counts(part, slot: np.ndarray, wanted: int) -> np.ndarray:
    """Counts of the low 16 bits of the keys of one part's values whose top 16 bits are wanted (``slot`` >= 0),
    int64 (wanted, 65536)."""
    low = np.zeros(wanted * _TOP, dtype=np.int64)
    for v in part():
        if len(v):
            u = np.ascontiguousarray(v, dtype=np.float32).view(np.uint32)
            s = slot[u >> np.uint32(16)]
            hit = np.flatnonzero(s >= 0)
            if len(hit):
                k = _keys(u[hit].view(np.float32))
                low += np.bincount(s[hit].astype(np.int64) * _TOP + (k & np.uint32(0xFFFF)), minlength=low.size)
    return low.reshape(wanted, _TOP)


def _second_pass(parts, slot, wanted, threads):
    if threads > 1 and len(parts) > 1:
        from concurrent.futures import ThreadPoolExecutor  # lazy: threads only for a split spill

        with ThreadPoolExecutor(min(threads, len(parts)), thread_name_prefix="hpe-percentiles") as ex:
            counts = list(ex.map(lambda p: _low_counts(p, slot, wanted), parts))
    else:
        counts = [_low_counts(p, slot, wanted) for p in parts]
    return sum(counts[1:], counts[0])
