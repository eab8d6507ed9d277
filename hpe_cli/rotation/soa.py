"""3x3 matrices as nested lists of 1-D arrays ("structure of arrays").

Batched ``np.matmul`` on ``(N, 3, 3)`` stacks is slow for 3x3 blocks, and
``R[:, i, j]`` columns are strided. Here a batch of matrices is a 3x3 nested
list whose entries are contiguous 1-D arrays, or Python floats for entries that
are the same in every row (the 0s and 1s of elemental rotations and of frame
changes). Products skip zero terms and unit factors, so an elemental product
or a signed-permutation frame change costs only the multiplications it needs.
"""

from __future__ import annotations

import numpy as np

from ..native import sin_cos

#: rows per block of the column kernels (:func:`hpe_cli.rotation.convert.soa_labels`, the rotation screen): their
#: few dozen temporaries (128 KB each) stay in the core's cache and in malloc's reused chunks, where
#: whole-batch ones (512 KB at 65,536 rows) are mapped and unmapped each time (page faults and TLB shootdowns
#: that cost more than the arithmetic, docs/performance.md); large enough that numpy's per-call cost is small
BLOCK = 16_384


def _prod(x, y):
    if isinstance(x, float):
        if x == 0.0 or (isinstance(y, float) and y == 0.0):
            return 0.0
        if x == 1.0:
            return y
        if x == -1.0:
            return -y
        return x * y
    if isinstance(y, float):
        if y == 0.0:
            return 0.0
        return x if y == 1.0 else (-x if y == -1.0 else x * y)
    return x * y


def _sum(terms):
    out = 0.0
    for t in terms:
        if isinstance(t, float) and t == 0.0:
            continue
        out = t if (isinstance(out, float) and out == 0.0) else out + t
    return out


def mul(X, Y):
    """Matrix product of two nested-list matrices."""
    return [[_sum(_prod(X[m][p], Y[p][n]) for p in range(3)) for n in range(3)] for m in range(3)]


def transpose(X):
    return [[X[n][m] for n in range(3)] for m in range(3)]


def constant(B):
    """A fixed 3x3 matrix as a nested list of floats."""
    return [[float(v) for v in row] for row in np.asarray(B, dtype=np.float64)]


def elemental(axis: int, angle):
    """Right-handed rotation about ``axis`` by ``angle`` (radians, 1-D array)."""
    s, c = sin_cos(angle)  # np.sin, np.cos: one C library call for both where that gives their bits
    M = [[0.0] * 3 for _ in range(3)]
    j, k = (axis + 1) % 3, (axis + 2) % 3
    M[axis][axis] = 1.0
    M[j][j] = c
    M[k][k] = c
    M[j][k] = -s
    M[k][j] = s
    return M


def from_array(R):
    """Views of an ``(N, 3, 3)`` array as a nested list."""
    R = np.asarray(R, dtype=np.float64)
    return [[R[..., m, n] for n in range(3)] for m in range(3)]


def blocks(n: int):
    """``(lo, hi)`` row ranges of :data:`BLOCK` rows covering ``0..n``."""
    return [(lo, min(n, lo + BLOCK)) for lo in range(0, n, BLOCK)]


def rows(X, lo: int, hi: int):
    """Rows ``lo:hi`` of a nested-list matrix (views; constant entries stay floats)."""
    return [[v if isinstance(v, float) else v[lo:hi] for v in row] for row in X]


def to_array(X, n: int) -> np.ndarray:
    """Assemble a nested list into an ``(n, 3, 3)`` array."""
    out = np.empty((n, 3, 3))
    for m in range(3):
        for k in range(3):
            out[:, m, k] = X[m][k]
    return out


def columns(X, n: int) -> list:
    """The nine entries in row-major order as contiguous 1-D arrays of length ``n``."""
    out = []
    for m in range(3):
        for k in range(3):
            v = X[m][k]
            out.append(np.full(n, v) if isinstance(v, float) else np.ascontiguousarray(v, dtype=np.float64))
    return out


def frobenius(X, Y) -> np.ndarray:
    """``||X - Y||_F`` per row (squares summed in row-major order)."""
    acc = 0.0
    for m in range(3):
        for k in range(3):
            d = X[m][k] - Y[m][k]
            if isinstance(acc, np.ndarray) and isinstance(d, np.ndarray) and d.shape == acc.shape:
                acc += np.multiply(d, d, out=d)  # the same sums as ``acc = acc + d * d``, without temporaries
            else:
                acc = acc + d * d
    return np.sqrt(acc)
