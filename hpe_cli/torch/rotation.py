"""Batched rotation kernels on tensors: any device, any floating dtype, no host transfers.

Every function mirrors a numpy kernel of :mod:`hpe_cli.rotation` and is derived
from the :class:`~hpe_cli.rotation.RotationSystem` definition (frame ``B``, the
three turns with their hands, intrinsic/extrinsic sequence, active/transposed
storage), never from per-system code:

- :func:`to_matrix` = ``RotationSystem.from_angles``; :func:`from_matrix` =
  ``RotationSystem.to_angles`` (both solutions, the lock flag and the lock distance,
  the same near-lock refinement and at-lock split as :mod:`hpe_cli.rotation.euler`);
- :func:`to_canonical` / :func:`from_canonical` = the system's maps to and from the
  canonical 300W-LP matrix ``A`` (``R_active = B A B^T``, stored active or transposed).

Shapes: angles ``(..., 3)`` in role order ``(pitch, yaw, roll)``, degrees;
matrices ``(..., 3, 3)``. Results keep the input's device and dtype. The kernels
never branch on tensor values in Python (``torch.where`` instead of masks), so a
CUDA batch stays on the GPU without synchronisation.

:func:`to_matrix`, :func:`to_canonical`, :func:`from_canonical`,
:func:`sixd_to_matrix`, :func:`matrix_to_sixd` are differentiable everywhere;
:func:`from_matrix` is differentiable away from gimbal lock (angles are not
defined smoothly there).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..rotation import euler as _euler
from ..rotation.systems import ROLES, RotationSystem, get_system

_DEG = 180.0 / math.pi
_AXIS = {"x": 0, "y": 1, "z": 2}

__all__ = [
    "angles_to_canonical",
    "canonical_to_angles",
    "elemental",
    "from_canonical",
    "from_matrix",
    "matrix_to_sixd",
    "sixd_to_matrix",
    "to_canonical",
    "to_matrix",
]


def _check_float(t, what):
    if not torch.is_tensor(t):
        t = torch.as_tensor(t, dtype=torch.float64)
    if not t.is_floating_point():
        t = t.to(torch.get_default_dtype())
    return t


def elemental(axis: int, angle):
    """Right-handed active rotations about ``axis`` (0, 1, 2) by ``angle`` radians: ``(..., 3, 3)``."""
    c, s = torch.cos(angle), torch.sin(angle)
    o, z = torch.ones_like(angle), torch.zeros_like(angle)
    if axis == 0:
        rows = ((o, z, z), (z, c, -s), (z, s, c))
    elif axis == 1:
        rows = ((c, z, s), (z, o, z), (-s, z, c))
    else:
        rows = ((c, -s, z), (s, c, z), (z, z, o))
    return torch.stack([torch.stack(r, -1) for r in rows], -2)


def _intrinsic(system: RotationSystem):
    seq = system.intrinsic_axes
    return [_AXIS[ch] for ch in seq], system._intrinsic_turns()


def to_matrix(angles, system) -> torch.Tensor:
    """Stored matrices from angles.

    Parameters
    ----------
    angles : Tensor, shape (..., 3)
        ``(pitch, yaw, roll)`` in degrees, any real values.
    system : str, path or RotationSystem

    Returns
    -------
    Tensor, shape (..., 3, 3)
        The system's stored matrices, same device and dtype.

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import to_matrix
    >>> to_matrix(torch.tensor([[0.0, 90.0, 0.0]], dtype=torch.float64), "300w_lp").round(decimals=12) + 0.0
    tensor([[[ 0.,  0., -1.],
             [ 0.,  1.,  0.],
             [ 1.,  0.,  0.]]], dtype=torch.float64)
    """
    system = get_system(system)
    angles = _check_float(angles, "angles")
    if angles.shape[-1:] != (3,):
        raise ValueError(f"expected angles of shape (..., 3), got {tuple(angles.shape)}")
    axes, turns = _intrinsic(system)
    idx = {r: n for n, r in enumerate(ROLES)}
    R = None
    for ax, t in zip(axes, turns):
        rad = angles[..., idx[t.angle]] * (t.sign() * math.pi / 180.0)
        E = elemental(ax, rad)
        R = E if R is None else R @ E
    if getattr(system, "angle_frame", "system") == "canonical":  # the turns build the canonical matrix
        R = from_canonical(R, system)
    return R


_CONST: dict = {}


def _const(M, like):
    """A constant 3x3 frame on ``like``'s device and dtype, copied there once (cached), never read back."""
    M = np.asarray(M, dtype=np.float64)
    key = (M.tobytes(), like.device, like.dtype)
    t = _CONST.get(key)
    if t is None:
        t = _CONST[key] = torch.as_tensor(M, dtype=like.dtype, device=like.device)
    return t


def _identity(system) -> bool:
    return bool(system._identity_frame)


def _model(system):
    return getattr(system, "M", system.B)


def to_canonical(R, system) -> torch.Tensor:
    """The canonical 300W-LP matrices ``A`` of stored matrices ``R`` (..., 3, 3).

    ``A = B^T R_active M`` with ``R_active`` = ``R`` (active storage) or ``R^T``
    (transposed), ``B`` the system's frame and ``M`` its head-model frame (``B``
    unless the system names a ``model_frame``).

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import to_canonical, to_matrix
    >>> R = to_matrix(torch.tensor([[10.0, 20.0, 30.0]]), "biwi")
    >>> A = to_canonical(R, "biwi")
    >>> bool(torch.allclose(A @ A.mT, torch.eye(3), atol=1e-6))
    True
    """
    system = get_system(system)
    R = _check_float(R, "R")
    if system.storage == "transposed":
        R = R.mT
    if _identity(system):
        return R
    return _const(system.B.T, R) @ R @ _const(_model(system), R)


def from_canonical(A, system) -> torch.Tensor:
    """Stored matrices of ``system`` from canonical matrices ``A`` (..., 3, 3); inverse of :func:`to_canonical`.

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import from_canonical
    >>> from_canonical(torch.eye(3, dtype=torch.float64)[None], "scipy_zyx").shape
    torch.Size([1, 3, 3])
    """
    system = get_system(system)
    A = _check_float(A, "A")
    X = A
    if not _identity(system):
        X = _const(system.B, A) @ A @ _const(_model(system).T, A)
    return X.mT if system.storage == "transposed" else X


def _parity(i, j, k):
    return 1.0 if (j - i) % 3 == 1 else -1.0


def _angle_about(M, i):
    j1, k1 = (i + 1) % 3, (i + 2) % 3
    return torch.atan2(M[..., k1, j1], M[..., j1, j1])


def _euler_solution1(R, seq_idx):
    """``(a, b, c, lock)`` of intrinsic right-handed matrices, as :func:`hpe_cli.rotation.euler.soa_to_euler`."""
    i, j, k = seq_idx
    if i == k:
        m = 3 - i - j
        e = _parity(i, j, m)
        lock = torch.sqrt(R[..., i, j] * R[..., i, j] + R[..., i, m] * R[..., i, m])
        b = torch.atan2(lock, R[..., i, i])
        a = torch.atan2(R[..., j, i], -e * R[..., m, i])
        c = torch.atan2(R[..., i, j], e * R[..., i, m])
    else:
        e = _parity(i, j, k)
        lock = torch.sqrt(R[..., i, i] * R[..., i, i] + R[..., i, j] * R[..., i, j])
        if e > 0:
            b = torch.atan2(R[..., i, k], lock)
            a = torch.atan2(-R[..., j, k], R[..., k, k])
            c = torch.atan2(-R[..., i, j], R[..., i, i])
        else:
            b = torch.atan2(-R[..., i, k], lock)
            a = torch.atan2(R[..., j, k], R[..., k, k])
            c = torch.atan2(R[..., i, j], R[..., i, i])
    # near the lock: solve a from the residual R Rk(c)^T Rj(b)^T (absorbs the error of c)
    Rj = elemental(j, b)
    tail = Rj @ elemental(k, c)
    a_ref = _angle_about(R @ tail.mT, i)
    near = lock < _euler.REFINE_BELOW
    a = torch.where(near, a_ref, a)
    # at the lock only a + sigma c is observable: half each
    total = _angle_about(R @ Rj.mT, i)
    sigma = torch.sign(Rj[..., i, k])
    locked = lock < _euler.SPLIT_EPS
    a = torch.where(locked, total / 2, a)
    c = torch.where(locked, sigma * total / 2, c)
    return a, b, c, lock


def _fold(d):
    """Degrees ``<= -180`` moved up by 360 (keeps (-180, 180])."""
    return torch.where(d <= -180.0, d + 360.0, d)


def from_matrix(R, system, gimbal_tol: float | None = None):
    """Both angle solutions of stored matrices, the lock flag and the lock distance.

    Parameters
    ----------
    R : Tensor, shape (..., 3, 3)
        The system's stored matrices (not validated).
    system : str, path or RotationSystem
    gimbal_tol : float, optional
        Lock tolerance on the lock distance (default: the system's ``gimbal_tol``).

    Returns
    -------
    primary, secondary : Tensor, shape (..., 3)
        ``(pitch, yaw, roll)`` degrees in (-180, 180]; ``primary`` follows the
        system's ``selection`` rule (``tait_bryan``, ``proper`` or ``whenet``).
    locked : Tensor of bool, shape (...)
        Within ``gimbal_tol`` of gimbal lock.
    lock : Tensor, shape (...)
        ``|cos b|`` (Tait-Bryan) or ``|sin b|`` (proper Euler) of the middle turn.

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import from_matrix, to_matrix
    >>> R = to_matrix(torch.tensor([[10.0, 30.0, -5.0]], dtype=torch.float64), "6drepnet")
    >>> p1, p2, locked, lock = from_matrix(R, "6drepnet")
    >>> p1.round(decimals=9), p2.round(decimals=9), locked
    (tensor([[10., 30., -5.]], dtype=torch.float64), tensor([[-170.,  150.,  175.]], dtype=torch.float64), tensor([False]))
    """
    system = get_system(system)
    R = _check_float(R, "R")
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected matrices of shape (..., 3, 3), got {tuple(R.shape)}")
    if getattr(system, "angle_frame", "system") == "canonical":  # the turns decompose the canonical matrix
        R = to_canonical(R, system)
    seq_idx, turns = _intrinsic(system)
    a, b, c, lock = _euler_solution1(R, seq_idx)
    proper = seq_idx[0] == seq_idx[2]
    first = {}
    for n, (t, v) in enumerate(zip(turns, (a, b, c))):
        first[t.angle] = (_fold(v * (_DEG if t.hand == "right" else -_DEG)), n == 1)
    p1, p2 = [], []
    for role in ROLES:
        d, middle = first[role]
        p1.append(d)
        if not middle:
            d2 = torch.where(d > 0, d - 180.0, d + 180.0)
        elif proper:
            d2 = -d
        else:
            d2 = torch.where(d < 0, -180.0 - d, 180.0 - d)
        p2.append(_fold(d2))
    if system.selection == "whenet":
        ok1 = (p1[0].abs() < 90) & (p1[2].abs() < 90)
        ok2 = (p2[0].abs() < 90) & (p2[2].abs() < 90)
        swap = ~ok1 & ok2
        p1, p2 = ([torch.where(swap, y, x) for x, y in zip(p1, p2)], [torch.where(swap, x, y) for x, y in zip(p1, p2)])
    tol = system.gimbal_tol if gimbal_tol is None else gimbal_tol
    return torch.stack(p1, -1), torch.stack(p2, -1), lock < tol, lock


def angles_to_canonical(angles, system) -> torch.Tensor:
    """Canonical matrices ``A`` (..., 3, 3) from a system's angles (..., 3), degrees."""
    return to_canonical(to_matrix(angles, system), system)


def canonical_to_angles(A, system):
    """``(primary, secondary, locked, lock)`` of canonical matrices in ``system`` (see :func:`from_matrix`)."""
    system = get_system(system)
    return from_matrix(from_canonical(A, system), system)


def sixd_to_matrix(x, eps: float = 1e-12) -> torch.Tensor:
    """Rotation matrices from the continuous 6-D representation (Zhou et al. 2019), differentiable.

    The 6 numbers are the matrix's **first two columns** ``(c0, c1)`` concatenated,
    as 6DRepNet's ``compute_rotation_matrix_from_ortho6d`` reads its network output
    (thohemp/6DRepNet ``sixdrepnet/utils.py``): ``c0`` normalised, ``c2 = c0 x c1``
    normalised, ``c1 = c2 x c0``.

    Parameters
    ----------
    x : Tensor, shape (..., 6)
    eps : float
        Floor of the norms (keeps gradients finite for degenerate inputs).

    Returns
    -------
    Tensor, shape (..., 3, 3)

    Examples
    --------
    >>> import torch
    >>> from hpe_cli.torch import sixd_to_matrix
    >>> sixd_to_matrix(torch.tensor([2.0, 0, 0, 1, 3, 0]))
    tensor([[1., 0., 0.],
            [0., 1., 0.],
            [0., 0., 1.]])
    """
    x = _check_float(x, "x")
    if x.shape[-1:] != (6,):
        raise ValueError(f"expected 6-D rotations of shape (..., 6), got {tuple(x.shape)}")
    c0 = x[..., 0:3] / x[..., 0:3].norm(dim=-1, keepdim=True).clamp_min(eps)
    c2 = torch.linalg.cross(c0, x[..., 3:6])
    c2 = c2 / c2.norm(dim=-1, keepdim=True).clamp_min(eps)
    c1 = torch.linalg.cross(c2, c0)
    return torch.stack([c0, c1, c2], -1)


def matrix_to_sixd(R) -> torch.Tensor:
    """The 6-D representation (first two columns, concatenated) of matrices (..., 3, 3): shape (..., 6)."""
    R = _check_float(R, "R")
    return torch.cat([R[..., :, 0], R[..., :, 1]], -1)
