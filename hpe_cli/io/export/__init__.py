"""Export layouts: one module per trainer, each written from that trainer's own loading code.

A layout receives, per split, the exported rows (a pandas DataFrame of label metadata, one row per head, with
the labels already in the layout's rotation system) and, for layouts that keep pixels themselves (``fsanet``,
``hf``), the encoded or raw crops as they are produced. Crop files of the folder layouts are written by the
worker processes straight into the staging folder, at the paths the layout's :meth:`Layout.relpath` names.

Every layout registers its class in :data:`LAYOUTS` (``@LAYOUTS.register()`` on a
:class:`~hpe_cli.io.export.base.Layout` subclass with a ``name``); ``hpe export --layout`` lists that table.
The built-in layouts are imported on first use (:mod:`hpe_cli.io.export.builtin`).
"""

from __future__ import annotations

from ...registry import Registry

#: name -> :class:`~hpe_cli.io.export.base.Layout` subclass (``hpe export --layout NAME``)
LAYOUTS = Registry("layout", loader="hpe_cli.io.export.builtin")


def get_layout(name: str, **options):
    """The layout object for ``name`` (one of :data:`LAYOUTS`), built with ``options``."""
    return LAYOUTS.get(name)(**options)
