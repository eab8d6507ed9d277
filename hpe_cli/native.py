"""hpe's optional compiled column kernels (``_hpe_kernels``, ``csrc/_hpe_kernels.c``), or None.

Each kernel is one C loop over a column where numpy takes a dozen passes or more: the key hashes of
``hpe evaluate``'s join and duplicate-key check (:func:`hpe_cli.io.key_hash.string_hashes`) and the row hashes of
``hpe audit``'s duplicate check, split by value half (:func:`hpe_cli.pipelines.audit.duplicates.key_hashes`,
:meth:`~hpe_cli.pipelines.audit.duplicates.Duplicates.file`). They compute integers only, so each gives the bits
of its numpy twin, which runs where the module was not built (no C
compiler at install time) or when ``HPE_KERNELS=numpy`` is set; ``tests/native/`` compares the two.
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
