"""64-bit hashes of Arrow text keys, and of their file stems, straight off the Arrow buffers (no Python strings).

Used to partition and pre-match the keys of two tables (``hpe evaluate``'s external join): equal strings get
equal hashes, and every match found by hash is verified on the strings themselves by the caller, so a
collision costs time, never a wrong pair.

The hash of the bytes ``b[s:e]`` of the column's data buffer is a polynomial ``sum b[i] P**(i - s)`` (mod
2**64), read off one prefix sum per batch as ``(S[e] - S[s]) * P**-s`` (``P`` odd, so it has an inverse
mod 2**64), mixed with the length and finished with SplitMix64's finaliser so that its low bits (the
partition) are well spread. Any substring costs the same, which gives the stem (the text after the last
``/`` or ``\\`` and before the last ``.`` after it: what ``^.*[\\/]|\\.[^.\\/]*$`` removed) for free.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from ..native import kernels

_P = np.uint64(0x100000001B3)  # FNV's 64-bit prime (odd)
_P_INV = np.uint64(pow(int(_P), -1, 1 << 64))
_LEN = np.uint64(0x9E3779B97F4A7C15)
_NULL = np.uint64(0xD6E8FEB86659FD93)


def mix(h: np.ndarray, scratch: np.ndarray | None = None) -> np.ndarray:
    """SplitMix64's finaliser, in place on the uint64 array ``h`` (uint64 arithmetic wraps); returns ``h``.

    ``scratch``: a uint64 array of ``h``'s length for the shifted copies (one is made when None). Also the
    finaliser of the audit's row hashes (:func:`hpe_cli.pipelines.audit.duplicates.key_hashes`).
    """
    t = np.empty_like(h) if scratch is None else scratch
    for shift, mult in ((30, 0xBF58476D1CE4E5B9), (27, 0x94D049BB133111EB), (31, None)):
        np.right_shift(h, np.uint64(shift), out=t)
        np.bitwise_xor(h, t, out=h)
        if mult is not None:
            np.multiply(h, np.uint64(mult), out=h)
    return h


_CACHE: dict = {}


def _powers(base: np.uint64, n: int) -> np.ndarray:
    """``base**0 .. base**(n-1)`` mod 2**64 (kept and grown: batches of one run need about the same length).

    Built by doubling, ``out[k:2k] = out[:k] * base**k``: about 22 whole-array products for millions of powers
    (a ``cumprod`` is one sequential pass, several times slower)."""
    have = _CACHE.get(int(base))
    if have is None or len(have) < n:
        m = max(n, 1 << 16, 0 if have is None else 2 * len(have))
        out = np.empty(m, dtype=np.uint64)  # a new array: readers of the old keep it
        out[0] = 1
        k = 1
        while k < m:
            step = min(k, m - k)
            np.multiply(out[:step], np.uint64(pow(int(base), k, 1 << 64)), out=out[k : k + step])
            k += step
        have = _CACHE[int(base)] = out
    return have[:n]


def string_hashes(arr, stems: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """``(hash of each string, hash of its file stem)``, uint64, of a pyarrow ``string``/``large_string`` array
    (or ``binary``/``large_binary``: the same bytes, the same hash).

    A null gets a hash of its own (its stem too). Equal strings, wherever they sit in whichever array, get
    equal hashes; a string that is its own stem (no folder, no suffix) gets the same hash for both.
    ``stems=False`` skips the stems (the second item is None).
    """

    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    large = pa.types.is_large_string(arr.type) or pa.types.is_large_binary(arr.type)
    if not (large or pa.types.is_string(arr.type) or pa.types.is_binary(arr.type)):
        raise TypeError(f"expected a string or binary array, got {arr.type}")
    n = len(arr)
    if n == 0:
        z = np.zeros(0, dtype=np.uint64)
        return z, (z if stems else None)
    width = np.int64 if large else np.int32
    bufs = arr.buffers()
    off = np.frombuffer(bufs[1], dtype=width, count=n + 1, offset=arr.offset * np.dtype(width).itemsize)
    off = off.astype(np.int64)
    base, top = int(off[0]), int(off[-1])
    data = (
        np.frombuffer(bufs[2], dtype=np.uint8)[base:top]
        if bufs[2] is not None and top > base
        else np.zeros(0, np.uint8)
    )
    k = kernels()
    if k is not None:  # the same hashes in one C loop (csrc/kernels/hashes.c); the numpy twin below
        off -= base
        valid = np.asarray(arr.is_valid().to_numpy(zero_copy_only=False), dtype=np.uint8) if arr.null_count else None
        hx, hs = np.empty(n, dtype=np.uint64), (np.empty(n, dtype=np.uint64) if stems else None)
        k.string_hashes(off, data, valid, hx, hs)
        return hx, hs
    start, end = off[:-1] - base, off[1:] - base
    L = len(data)
    # S[j] = sum_{i<j} b[i] P**i ;  hash(s, e) = (S[e] - S[s]) * P**-s, then the length mixed in
    pw = _powers(_P, L + 1)
    S = np.empty(L + 1, dtype=np.uint64)
    S[0] = 0
    np.multiply(data, pw[:L], out=S[1:], dtype=np.uint64)  # no uint64 copy of the bytes
    np.cumsum(S[1:], out=S[1:])
    inv = _powers(_P_INV, L + 1)

    def sub(s, e):
        h = S[e]
        h -= S[s]
        h *= inv[s]
        ln = (e - s).astype(np.uint64)
        ln *= _LEN
        h ^= ln
        return mix(h)

    hx = sub(start, end)
    if not stems:
        if arr.null_count:
            hx = np.where(np.asarray(arr.is_valid().to_numpy(zero_copy_only=False), dtype=bool), hx, _NULL)
        return hx, None
    # the stem: after the last / or \ ; before the last . after that
    slash = np.flatnonzero((data == 47) | (data == 92))
    dot = np.flatnonzero(data == 46)
    s0 = start.copy()
    if len(slash):
        j = np.searchsorted(slash, end, side="left") - 1
        last = np.where(j >= 0, slash[np.maximum(j, 0)], -1)
        s0 = np.where(last >= start, last + 1, start)
    e0 = end.copy()
    if len(dot):
        j = np.searchsorted(dot, end, side="left") - 1
        last = np.where(j >= 0, dot[np.maximum(j, 0)], -1)
        e0 = np.where(last >= s0, last, end)
    other = np.flatnonzero((s0 != start) | (e0 != end))  # the rows whose stem is not the whole text
    hs = hx
    if len(other):
        hs = hx.copy()
        hs[other] = sub(s0[other], e0[other])
    if arr.null_count:
        valid = np.asarray(arr.is_valid().to_numpy(zero_copy_only=False), dtype=bool)
        hx = np.where(valid, hx, _NULL)
        hs = np.where(valid, hs, _NULL)
    return hx, hs
