"""hpe's optional compiled column kernels (``_hpe_kernels``, ``csrc/_hpe_kernels.c``), or None.

Each kernel is one C loop over a column where numpy takes a dozen passes or more: the key hashes of
``hpe evaluate``'s join and duplicate-key check (:func:`hpe_cli.io.key_hash.string_hashes`), the row hashes of
``hpe audit``'s duplicate check and their split by value half (:func:`hpe_cli.pipelines.audit.duplicates.key_hashes`,
:meth:`~hpe_cli.pipelines.audit.duplicates.Duplicates.file`), the audit's angle screen, and the sine and cosine
of the matrices built from angles (:func:`sin_cos`). All but the last compute integers and comparisons only, so
each gives the bits of its numpy twin; :func:`sin_cos` is used only where it gives numpy's bits on a probe. The
numpy twins run where the module was not built (no C compiler at install time) or when ``HPE_KERNELS=numpy`` is
set; ``tests/native/`` compares the two.
"""

from __future__ import annotations

import os

_STATE: dict = {}


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
        _STATE["module"] = _hpe_kernels
    return _STATE["module"]


#: below this many values numpy's two calls cost less than the kernel's buffer handling
_SIN_COS_MIN = 64


def _probe_angles():
    """Angles whose sine and cosine the kernel must give with numpy's bits before it is used: whole and half
    degrees (what labels hold), multiples of pi/4, random radians near and far from 0, tiny, huge and special
    values."""
    import numpy as np

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
    k = kernels()
    if k is None:
        return None
    if "sin_cos" not in _STATE:
        import numpy as np

        x = _probe_angles()
        s, c = np.empty_like(x), np.empty_like(x)
        k.sin_cos(x, s, c)
        with np.errstate(invalid="ignore"):
            same = np.array_equal(s.view(np.int64), np.sin(x).view(np.int64)) and np.array_equal(
                c.view(np.int64), np.cos(x).view(np.int64)
            )
        _STATE["sin_cos"] = same
    return k if _STATE["sin_cos"] else None


def sin_cos(x):
    """``(np.sin(x), np.cos(x))`` of a float64 array, in one C library call per value where the kernel is built and
    gives numpy's bits on this machine (:func:`_sin_cos_kernel`), else numpy's two calls: the same arrays either
    way, new ones (about 0.7x the time of numpy's two calls)."""
    import numpy as np

    x = np.asarray(x, dtype=np.float64)
    k = _sin_cos_kernel() if x.ndim >= 1 and x.size >= _SIN_COS_MIN else None
    if k is None:
        return np.sin(x), np.cos(x)
    x = np.ascontiguousarray(x)
    s, c = np.empty(x.shape), np.empty(x.shape)
    k.sin_cos(x.reshape(-1), s.reshape(-1), c.reshape(-1))
    return s, c
