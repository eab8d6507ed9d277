"""hpe: head-pose labels done right -- rotation systems, conversions, readers, audit, augmentation.

The Python API (``import hpe_cli as hpe``)
------------------------------------------
Every name below lives in :mod:`hpe_cli.api` and is imported on first use, so
``import hpe_cli`` stays fast and never pulls in torch, pandas, pyarrow, SciPy or matplotlib.

Angles cross the API in **role order** ``(pitch, yaw, roll)``, in **degrees**,
shape ``(N, 3)``, whatever order and units a dataset stores on disk. Matrices
are a system's *stored* matrices, shape ``(N, 3, 3)``. The canonical matrix is
the 300W-LP active matrix ``A`` (x = subject's left, y = up, z = out of the face).

=====================  ==========================================================
``get_system``         a :class:`~hpe_cli.rotation.RotationSystem` by name, TOML path or as is
``systems``            every built-in system, by name
``convert``            angles / matrices / rotation vectors / quaternions of one system
                       into the labels of another (a :class:`~hpe_cli.rotation.Conversion`)
``read_labels``        a label table and its rotation system (Parquet metadata, ``.mat``, BIWI)
``write_labels``       a label table written atomically, with its system in the metadata
``convert_file``       ``hpe convert`` on a file (the same pipeline; system from the file's metadata)
``audit_file``         ``hpe audit`` on a file (the same pipeline), its JSON report
``evaluate_files``     ``hpe evaluate`` on two files (the same pipeline), its JSON report
``audit``              per-row label checks (gimbal lock, non-canonical, out of range...)
``evaluate``           the evaluation report of predictions against ground truth
``augment_sample``     labels, landmarks and box of one sample after a flip / rotation / mirror
``augment_batch``      the same for N samples at once
``augment_file``       ``hpe augment`` on a file (the same pipeline), its summary
``infer_system``       ``hpe infer`` on a table or on code (the same pipeline), its JSON report
``draw_axes``          Hopenet-style pose axes drawn onto an image
``geodesic``           the rotation angle between two labels, degrees
``landmark_pose``      head rotation fitted to 2-D landmarks alone (``hpe audit --consistency``'s evidence)
``relabel_panoptic``   ``hpe relabel-panoptic`` on CMU Panoptic sequences (the same pipeline)
``relabel_agora``      ``hpe relabel-agora`` on AGORA dataframes (the same pipeline)
``biwi_file``          ``hpe biwi`` on BIWI's files (the same pipeline)
=====================  ==========================================================

The optional tensor side (``pip install hpe-cli[torch]``) lives in :mod:`hpe_cli.torch`.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

#: the public API, in :mod:`hpe_cli.api`; resolved lazily by :func:`__getattr__`
_API = (
    "get_system",
    "systems",
    "convert",
    "read_labels",
    "write_labels",
    "audit",
    "evaluate",
    "augment_sample",
    "augment_batch",
    "draw_axes",
    "geodesic",
    "LabelTable",
    "STORAGE_KINDS",
    "convert_file",
    "audit_file",
    "evaluate_files",
    "landmark_pose",
    "view_file",
    "draw_file",
    "augment_file",
    "infer_system",
    "relabel_panoptic",
    "relabel_agora",
    "biwi_file",
)

#: names resolved lazily by :func:`__getattr__`: name -> (module, attribute)
_LAZY = {
    **{name: ("hpe_cli.api", name) for name in _API},
    "RotationSystem": ("hpe_cli.rotation.systems", "RotationSystem"),
    "Conversion": ("hpe_cli.rotation.convert", "Conversion"),
    "Augmented": ("hpe_cli.geometry.augment", "Augmented"),
    "HpeError": ("hpe_cli.errors", "HpeError"),
}

__all__ = [n for n in _LAZY if n != "STORAGE_KINDS"]


def __getattr__(name):
    if name in _LAZY:
        module, attr = _LAZY[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'hpe_cli' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
