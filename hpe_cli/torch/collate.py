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
it), so a batch crosses to the main process as one segment. Other values (TVTensors,
strings, ...) go through ``default_collate`` key by key, as before.
"""
from __future__ import annotations

import torch
from torch.utils.data import get_worker_info
from torch.utils.data._utils.collate import collate, default_collate_fn_map

_ALIGN = 64


class Sample(dict):
    """A sample of :class:`~hpe_cli.torch.HeadPoseDataset`: a plain ``dict`` that batches into one block."""

    __slots__ = ()


def _plan(batch, key):
    """``(dtype, shape)`` when ``batch[*][key]`` packs (plain CPU tensors alike, or ints), else None."""
    first = batch[0][key]
    if type(first) is torch.Tensor:
        if first.device.type != "cpu" or first.is_sparse or first.requires_grad:
            return None
        for s in batch:
            v = s[key]
            if type(v) is not torch.Tensor or v.shape != first.shape or v.dtype != first.dtype or \
                    v.device.type != "cpu":
                return None
        return first.dtype, tuple(first.shape)
    if type(first) is int and all(type(s[key]) is int for s in batch):
        return torch.int64, ()
    return None


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
        view = buf[offset:offset + size].view(dtype).view(n, *shape)
        values = [s[key] for s in batch]
        if shape == () and type(values[0]) is int:
            view.copy_(torch.tensor(values, dtype=torch.int64))
        else:
            torch.stack(values, 0, out=view)
        out[key] = view
    return out


default_collate_fn_map[Sample] = collate_samples
