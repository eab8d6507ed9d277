"""hpe's optional compiled column kernels (``_hpe_kernels``, ``csrc/_hpe_kernels.c``), or None.

Each kernel is one C loop over a column where numpy takes a dozen passes or more: the key hashes of
``hpe evaluate``'s join and duplicate-key check (:func:`hpe_cli.io.key_hash.string_hashes`), the row hashes of
``hpe audit``'s duplicate check and their split by value half (:func:`hpe_cli.pipelines.audit.duplicates.key_hashes`,
:meth:`~hpe_cli.pipelines.audit.duplicates.Duplicates.file`), the audit's angle screen, and the sine and cosine
of the matrices built from angles (:func:`sin_cos`), and the geodesic, column-angle and Frobenius errors of
``hpe evaluate``'s core metrics (:func:`core_errors`). The hashes and the screen compute integers and comparisons
only, so each gives the bits of its numpy twin; the others use the C library's sine, cosine and ``atan2`` (besides
IEEE arithmetic in numpy's order), each only where it gives numpy's bits on a probe of values. The
numpy twins run where the module was not built (no C compiler at install time) or when ``HPE_KERNELS=numpy`` is
set; ``tests/native/`` compares the two.
"""

from __future__ import annotations

import os

import numpy as np

_STATE: dict = {}

#: the functions this version calls: a module that lacks one is treated as not built
KERNELS = (
    "string_hashes",
    "row_hash_add",
    "mix",
    "split_top_bit",
    "angle_screen",
    "sin_cos",
    "core_errors",
    "atan2",
    "repeated_values",
    "bucket_file",
    "bucket_repeats",
)


def kernels():
    """The ``_hpe_kernels`` module, or None when it is not built or ``HPE_KERNELS=numpy`` asks for the numpy twins
    (read on each call: tests switch it)."""
    if os.environ.get("HPE_KERNELS", "").strip().lower() == "numpy":
        return None
    if "module" not in _STATE:
        try:
            import _hpe_kernels
        except ImportError:
            _hpe_kernels = None
        if _hpe_kernels is not None and not all(hasattr(_hpe_kernels, f) for f in KERNELS):
            _hpe_kernels = None  # a build from older sources (a checkout's stale .so): the numpy twins run
        _STATE["module"] = _hpe_kernels
    return _STATE["module"]


#: below this many rows numpy's calls cost less than a kernel's buffer handling
_MIN_ROWS = 64


def _agreeing(name: str, compare):
    """The kernels, if the C library function ``name`` gives numpy's bits on its probe, else None. ``compare(k)``
    runs the probe and returns ``[(kernel result, numpy result), ...]``; it runs once a process."""
    k = kernels()
    if k is None:
        return None
    if name not in _STATE:
        with np.errstate(invalid="ignore"):
            _STATE[name] = all(np.array_equal(a.view(np.int64), b.view(np.int64)) for a, b in compare(k))
    return k if _STATE[name] else None


def _probe_angles():
    """Angles whose sine and cosine the kernel must give with numpy's bits before it is used: whole and half
    degrees (what labels hold), multiples of pi/4, random radians near and far from 0, tiny, huge and special
    values."""
    rng = np.random.default_rng(20261128)
    return np.concatenate(
        [
            np.deg2rad(np.arange(-720.0, 720.5, 0.5)),
            np.arange(-32, 33) * (np.pi / 4),
            rng.uniform(-7.0, 7.0, 4096),
            rng.uniform(-1e6, 1e6, 512),
            rng.standard_normal(256) * 1e-9,
            [0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e22, -1e22, 1e300, np.inf, -np.inf, np.nan],
        ]
    )


def _sin_cos_kernel():
    """The kernel, if it gives numpy's bits on :func:`_probe_angles` (checked once a process), else None."""

    def compare(k):
        x = _probe_angles()
        s, c = np.empty_like(x), np.empty_like(x)
        k.sin_cos(x, s, c)
        return [(s, np.sin(x)), (c, np.cos(x))]

    return _agreeing("sin_cos", compare)


def sin_cos(x):
    """``(np.sin(x), np.cos(x))`` of a float64 array, in one C library call per value where the kernel is built and
    gives numpy's bits on this machine (:func:`_sin_cos_kernel`), else numpy's two calls: the same arrays either
    way, new ones (about 0.7x the time of numpy's two calls)."""
    x = np.asarray(x, dtype=np.float64)
    k = _sin_cos_kernel() if x.ndim >= 1 and x.size >= _MIN_ROWS else None
    if k is None:
        return np.sin(x), np.cos(x)
    x = np.ascontiguousarray(x)
    s, c = np.empty(x.shape), np.empty(x.shape)
    k.sin_cos(x.reshape(-1), s.reshape(-1), c.reshape(-1))
    return s, c


def _atan2_probe():
    """``(y, x)`` pairs whose ``atan2`` the kernels must give with numpy's bits before they use it: every sign and
    quadrant, the axes, zeros of both signs, tiny, huge and special values, and the (sin, cos) pairs of whole and
    half degrees."""
    rng = np.random.default_rng(20261129)
    a = np.deg2rad(np.arange(-720.0, 720.5, 0.5))
    special = np.array([0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 1e-300, 1e300, -1e300, np.inf, -np.inf, np.nan])
    sy, sx = (g.ravel() for g in np.meshgrid(special, special))
    return (
        np.concatenate([np.sin(a), rng.standard_normal(4096) * 10.0 ** rng.uniform(-20, 20, 4096), sy]),
        np.concatenate([np.cos(a), rng.standard_normal(4096) * 10.0 ** rng.uniform(-20, 20, 4096), sx]),
    )


def _atan2_kernels():
    """The kernels, if the C library's ``atan2`` gives numpy's bits on :func:`_atan2_probe` (checked once a
    process), else None."""

    def compare(k):
        y, x = _atan2_probe()
        out = np.empty_like(y)
        k.atan2(y, x, out)
        return [(out, np.arctan2(y, x))]

    return _agreeing("atan2", compare)


def core_errors(P, G):
    """``(geodesic (N,), column angles (N, 3), Frobenius distance (N,))`` of nested 3x3 lists of columns (arrays or
    floats) in one C loop, or None where the kernels are not built or the C library's ``atan2`` does not give
    numpy's bits (then :mod:`hpe_cli.metrics.rotation_errors` computes them: the same numbers)."""
    k = _atan2_kernels()
    if k is None:
        return None
    n = int(np.broadcast(*[x for row in P for x in row], *[x for row in G for x in row]).shape[0])
    if n < _MIN_ROWS:
        return None

    def cols(X):
        return [np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=np.float64), (n,))) for row in X for v in row]

    geo, maev, fro = np.empty(n), np.empty((n, 3)), np.empty(n)
    k.core_errors(cols(P), cols(G), geo, maev, fro)
    return geo, maev, fro
