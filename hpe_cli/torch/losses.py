"""Losses and metrics on rotation matrices (tensors, differentiable, any device)."""

from __future__ import annotations

import math

import torch

__all__ = ["geodesic", "geodesic_loss", "maev"]


def _safe_norm(v, dim=-1):
    """Euclidean norm whose gradient is 0 (not NaN) where the vector is exactly 0."""
    n2 = (v * v).sum(dim)
    pos = n2 > 0
    return torch.where(pos, torch.sqrt(torch.where(pos, n2, torch.ones_like(n2))), torch.zeros_like(n2))


def geodesic(R1, R2) -> torch.Tensor:
    """Rotation angle of ``R1^T R2`` in radians, in [0, pi], shape (...).

    ``atan2(|skew(M)|, (trace(M) - 1) / 2)`` with ``M = R1^T R2``: accurate near 0
    and pi (where ``acos`` of the trace loses half the digits and has an infinite
    derivative), and its gradient is finite everywhere, including exactly 0 and pi.

    Parameters
    ----------
    R1, R2 : Tensor, shape (..., 3, 3)
        Rotation matrices of one system (the angle is the same in every system).

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import geodesic, to_matrix
    >>> R = to_matrix(torch.tensor([[0.0, 0.0, 0.0], [0.0, 180.0, 0.0]], dtype=torch.float64), "300w_lp")
    >>> torch.rad2deg(geodesic(R[:1], R))
    tensor([  0., 180.], dtype=torch.float64)
    """
    M = R1.mT @ R2
    skew = torch.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1)
    sin = 0.5 * _safe_norm(skew)
    cos = 0.5 * (M[..., 0, 0] + M[..., 1, 1] + M[..., 2, 2] - 1.0)
    return torch.atan2(sin, cos)


def geodesic_loss(pred, target, reduction: str = "mean", degrees: bool = False) -> torch.Tensor:
    """Geodesic distance between predicted and target rotation matrices, as a training loss.

    Parameters
    ----------
    pred, target : Tensor, shape (N, 3, 3)
        Rotation matrices (e.g. :func:`~hpe_cli.torch.sixd_to_matrix` of a network's output).
    reduction : {"mean", "sum", "none"}
    degrees : bool
        Degrees instead of radians.

    Returns
    -------
    Tensor
        Scalar, or (N,) for ``reduction="none"``; radians in [0, pi] per row.

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import geodesic_loss
    >>> I = torch.eye(3).expand(2, 3, 3)
    >>> R = torch.tensor([[[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]]).expand(2, 3, 3)
    >>> geodesic_loss(I, R, degrees=True)
    tensor(90.)
    """
    d = geodesic(pred, target)
    if degrees:
        d = d * (180.0 / math.pi)
    if reduction == "mean":
        return d.mean()
    if reduction == "sum":
        return d.sum()
    if reduction == "none":
        return d
    raise ValueError(f"expected reduction 'mean', 'sum' or 'none', got {reduction!r}")


def maev(pred, target, reduction: str = "mean") -> torch.Tensor:
    """Mean absolute error of vectors (MAEV, TriNet, Cao et al. 2021), degrees.

    The mean over the three columns (the head's left, up and forward axes) of the
    angle between the predicted and the target column vector.

    Parameters
    ----------
    pred, target : Tensor, shape (N, 3, 3)
        Canonical (or any one system's active) rotation matrices.
    reduction : {"mean", "none"}
        ``none`` gives (N, 3): the per-vector angles.

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import maev
    >>> R = torch.tensor([[[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]], dtype=torch.float64)
    >>> maev(torch.eye(3, dtype=torch.float64)[None], R)
    tensor(60., dtype=torch.float64)
    """
    a, b = pred.mT, target.mT  # rows = the three column vectors
    cross = _safe_norm(torch.linalg.cross(a, b))
    dot = (a * b).sum(-1)
    ang = torch.rad2deg(torch.atan2(cross, dot))
    if reduction == "mean":
        return ang.mean()
    if reduction == "none":
        return ang
    raise ValueError(f"expected reduction 'mean' or 'none', got {reduction!r}")
