"""Export layouts: one module per trainer, each written from that trainer's own loading code.

A layout receives, per split, the exported rows (a pandas DataFrame of label metadata, one row per head, with
the labels already in the layout's rotation system) and, for layouts that keep pixels themselves (``fsanet``,
``hf``), the encoded or raw crops as they are produced. Crop files of the folder layouts are written by the
worker processes straight into the staging folder, at the paths the layout's :meth:`Layout.relpath` names.
"""

from __future__ import annotations

LAYOUTS = ("whenet", "6drepnet", "directmhp", "fsanet", "hf")


def get_layout(name: str, **options):
    """The layout object for ``name`` (one of :data:`LAYOUTS`)."""
    if name == "whenet":
        from .whenet import WhenetLayout as cls
    elif name == "6drepnet":
        from .sixdrepnet import SixDRepNetLayout as cls
    elif name == "directmhp":
        from .directmhp import DirectMHPLayout as cls
    elif name == "fsanet":
        from .fsanet import FSANetLayout as cls
    elif name == "hf":
        from .hf import HFLayout as cls
    else:
        raise ValueError(f"expected a layout in {', '.join(LAYOUTS)}, got {name!r}")
    return cls(**options)
