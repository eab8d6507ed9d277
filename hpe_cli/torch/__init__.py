"""PyTorch side of hpe (extra ``hpe-cli[torch]``): tensor kernels, losses, a Dataset, torchvision v2 transforms.

Never imported by the core package. Everything works on tensors of any device and
floating dtype; see :mod:`hpe_cli.torch.rotation` (conversions),
:mod:`hpe_cli.torch.losses` (``geodesic_loss``, ``maev``),
:mod:`hpe_cli.torch.transforms` (``HeadPose`` TVTensor and its kernels) and
:mod:`hpe_cli.torch.dataset` (``HeadPoseDataset``).

Examples
--------
>>> import torch
>>> import hpe_cli.torch as ht
>>> R = ht.to_matrix(torch.tensor([[10.0, -40.0, 5.0]], dtype=torch.float64), "6drepnet")
>>> A = ht.to_canonical(R, "6drepnet")
>>> ht.canonical_to_angles(A, "300w_lp")[0].round(decimals=6)
tensor([[ 10., -40.,   5.]], dtype=torch.float64)
"""

from . import transforms
from .dataset import HeadPoseDataset
from .losses import geodesic, geodesic_loss, maev
from .rotation import (
    angles_to_canonical,
    canonical_to_angles,
    elemental,
    from_canonical,
    from_matrix,
    matrix_to_sixd,
    sixd_to_matrix,
    to_canonical,
    to_matrix,
)
from .transforms import HeadPose, PermuteLandmarks, UndefinedPoseError

__all__ = [
    "HeadPose",
    "HeadPoseDataset",
    "PermuteLandmarks",
    "UndefinedPoseError",
    "angles_to_canonical",
    "canonical_to_angles",
    "elemental",
    "from_canonical",
    "from_matrix",
    "geodesic",
    "geodesic_loss",
    "maev",
    "matrix_to_sixd",
    "sixd_to_matrix",
    "to_canonical",
    "to_matrix",
    "transforms",
]
