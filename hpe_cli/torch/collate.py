"""Batching :class:`~hpe_cli.torch.HeadPoseDataset` samples into one block of memory (one shared segment per batch).

``DataLoader``'s ``default_collate`` stacks every key of a sample dict into its own tensor;
in a worker process each of them is a separate shared-memory segment, and each segment is
one file-descriptor hand-over (a socket round trip) to the main process. A head-pose
sample has nine keys (image, box, landmarks, matrix, angles, canonical, two flags, index):
nine hand-overs per batch where a bare image loader has one. Measured on 2 busy cores,
those eight extra segments cost ~0.8 ms of CPU per sample at ``batch_size=16``, more than
the crop, resize and flip together.

:func:`collate_samples` is registered for :class:`Sample` in torch's documented extension
point ``torch.utils.data._utils.collate.default_collate_fn_map`` (see
``torch.utils.data.default_collate``), so a plain ``DataLoader(dataset, batch_size=...)``
uses it: the same values, dtypes and shapes as ``default_collate`` gives, but all plain
tensors and Python ints of the batch live in one storage (each key a contiguous view of
it), so a batch crosses to the main process as one segment, and large tensors (the
images) are copied with numpy (:func:`_copy_numpy`: twice as fast as ``torch.stack``
for channels-last views). Other values (TVTensors, strings, ...) go through
``default_collate`` key by key, as before.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.utils.data import get_worker_info
from torch.utils.data._utils.collate import collate, default_collate_fn_map

_ALIGN = 64
_NUMPY_FROM = 4096  # elements per sample from which numpy copies (below: one torch.stack call)


class Sample(dict):
    """A sample of :class:`~hpe_cli.torch.HeadPoseDataset`: a plain ``dict`` that batches into one block."""

    __slots__ = ()


def _plan(batch, key):
    """``(dtype, shape)`` of ``batch[0][key]`` when the key packs (plain CPU tensors, or ints), else None.

    Only the types of the other samples' values are checked here; a shape or dtype that
    differs is caught when they are copied (numpy) or stacked (torch, as ``default_collate``).
    """
    first = batch[0][key]
    if type(first) is torch.Tensor:
        if first.device.type != "cpu" or first.layout != torch.strided or first.requires_grad:
            return None
        if all(type(s[key]) is torch.Tensor for s in batch):
            return first.dtype, tuple(first.shape)
        return None
    if type(first) is int and all(type(s[key]) is int for s in batch):
        return torch.int64, ()
    return None


def _copy_numpy(values, view) -> bool:
    """Copy each tensor into ``view[k]`` with numpy (False: a dtype numpy lacks, nothing copied).

    numpy's strided copy moves a channels-last (3, H, W) view of an HWC image into a
    contiguous slot about twice as fast as ``torch.stack`` does (62 vs 120 us for a
    224 x 224 uint8 image, 1 thread); the bytes are the same.
    """
    try:
        dst = view.numpy()
        src = [v.numpy() for v in values]
    except (TypeError, RuntimeError):  # e.g. bfloat16, a tensor with the conj/neg bit or needing grad
        return False
    if any(a.shape != dst.shape[1:] or a.dtype != dst.dtype for a in src):  # no broadcast, no cast
        return False
    for k, a in enumerate(src):
        np.copyto(dst[k], a)
    return True


def collate_samples(batch, *, collate_fn_map=None):
    """``default_collate`` of a list of :class:`Sample`, the packable keys in one (shared, in a worker) storage.

    Returns a plain ``dict`` with the keys of ``batch[0]``: tensors stacked on a new first
    dimension, ints as an int64 tensor, anything else as ``default_collate`` does it.
    """
    n = len(batch)
    plans, total = {}, 0
    for key in batch[0]:
        plan = _plan(batch, key)
        if plan is not None:
            dtype, shape = plan
            size = n * torch.Size(shape).numel() * torch.empty((), dtype=dtype).element_size()
            plans[key] = (total, size, dtype, shape)
            total += -(-size // _ALIGN) * _ALIGN
    buf = None
    if plans:
        if get_worker_info() is not None:  # as default_collate: straight into shared memory
            storage = torch.empty(0, dtype=torch.uint8)._typed_storage()._new_shared(total, device="cpu")
            buf = torch.empty(0, dtype=torch.uint8).new(storage)
        else:
            buf = torch.empty(total, dtype=torch.uint8)
    out = {}
    for key in batch[0]:
        if key not in plans:
            out[key] = collate([s[key] for s in batch], collate_fn_map=collate_fn_map or default_collate_fn_map)
            continue
        offset, size, dtype, shape = plans[key]
        view = buf[offset : offset + size].view(dtype).view(n, *shape)
        values = [s[key] for s in batch]
        if shape == () and type(values[0]) is int:
            view.copy_(torch.tensor(values, dtype=torch.int64))
        elif view[0].numel() < _NUMPY_FROM or not _copy_numpy(values, view):
            try:
                torch.stack(values, 0, out=view)
            except RuntimeError:  # sizes or devices differ: default_collate's own result or error
                view = collate(values, collate_fn_map=collate_fn_map or default_collate_fn_map)
        out[key] = view
    return out


default_collate_fn_map[Sample] = collate_samples
