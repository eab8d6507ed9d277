"""Exact percentiles of float32 values read piece by piece: memory flat in the number of values.

``np.percentile`` needs the whole array (and partitions a copy of it). Its linear method reads only two order
statistics per percentile, the ``floor`` and ``ceil`` of a virtual index, and interpolates between them. Here those
order statistics are found by a two-level radix select over the values' bits: one pass counts the top 16 bits of
each value's order-preserving 32-bit key, a second pass counts the low 16 bits inside the few top buckets that hold
a wanted rank, which gives each wanted value exactly. The interpolation is then numpy's own (its private
``_lerp`` and index helpers, so the numbers are ``np.percentile``'s to the bit; tested against it), with
``np.percentile`` on the whole array as the fallback where those helpers are missing or a NaN is present.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

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


def percentiles_of_pieces(pieces: Callable[[], Iterable[np.ndarray]], n: int, q) -> np.ndarray | None:
    """``np.percentile(all values, q)`` of ``n`` float32 values that ``pieces()`` yields piece by piece.

    Parameters
    ----------
    pieces : callable
        Returns a fresh iterable of float32 arrays (the values in any order), called twice.
    n : int
        The number of values (> 0).
    q : sequence of float
        Percentiles in [0, 100].

    Returns
    -------
    ndarray (len(q),) or None
        The percentiles, equal to ``np.percentile``'s on the concatenated values; None when a value is NaN or
        this numpy lacks the helpers (the caller then takes ``np.percentile`` on the whole array).
    """
    got = _ranks(n, np.true_divide(np.asarray(q, dtype=np.float64), 100))
    if got is None or n <= 0:
        return None
    prev, nxt, gamma, lerp = got
    ranks = np.unique(np.concatenate([prev, nxt]))
    top = np.zeros(_TOP, dtype=np.int64)
    for v in pieces():
        if len(v):
            k = _keys(v)
            if np.isnan(v).any():
                return None
            top += np.bincount(k >> np.uint32(16), minlength=_TOP)
    cum = np.cumsum(top)
    if cum[-1] != n:
        raise ValueError(f"expected {n} values, got {int(cum[-1])}")
    bucket = np.searchsorted(cum, ranks, side="right")  # the top bucket of each wanted rank
    low_rank = ranks - np.where(bucket > 0, cum[np.maximum(bucket - 1, 0)], 0)
    wanted = np.unique(bucket)
    low = np.zeros((len(wanted), _TOP), dtype=np.int64)
    for v in pieces():
        if len(v):
            k = _keys(v)
            b = (k >> np.uint32(16)).astype(np.int64)
            j = np.searchsorted(wanted, b)
            hit = (j < len(wanted)) & (wanted[np.minimum(j, len(wanted) - 1)] == b)
            if hit.any():
                flat = j[hit] * _TOP + (k[hit] & np.uint32(0xFFFF)).astype(np.int64)
                low += np.bincount(flat, minlength=low.size).reshape(low.shape)
    key_of = {}
    for r, b, lr in zip(ranks, bucket, low_rank):
        row = np.cumsum(low[int(np.searchsorted(wanted, b))])
        key_of[int(r)] = (int(b) << 16) | int(np.searchsorted(row, lr, side="right"))
    order = _values(np.array([key_of[int(r)] for r in ranks], dtype=np.uint32))
    at = dict(zip((int(r) for r in ranks), order))
    a = np.array([at[int(r)] for r in prev], dtype=np.float32)
    b = np.array([at[int(r)] for r in nxt], dtype=np.float32)
    return np.asarray(lerp(a, b, gamma))
