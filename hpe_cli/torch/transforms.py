"""torchvision v2 transforms that move head poses with the image.

:class:`HeadPose` is a TVTensor holding the **canonical 300W-LP rotation matrix**
of each face, shape ``(N, 3, 3)`` (or ``(..., 3, 3)``), plus the image's
``canvas_size`` ``(H, W)``. Kernels are registered with
``torchvision.transforms.v2.functional.register_kernel``, so any ``v2`` pipeline
moves image, ``BoundingBoxes``, ``KeyPoints`` and ``HeadPose`` together::

    from torchvision.transforms import v2
    from hpe_cli.torch import HeadPose, transforms as T

    pose = HeadPose(A, canvas_size=(H, W))          # A: canonical matrices, e.g. to_canonical(R, system)
    pipe = v2.Compose([T.RandomHorizontalFlip(scheme="ibug68"), v2.RandomRotation(30),
                       v2.RandomResizedCrop(224, ratio=(1, 1)), v2.ToDtype(torch.float32, scale=True)])
    image, boxes, points, pose = pipe(image, boxes, points, pose)

The maths is that of :mod:`hpe_cli.geometry.augment` (the docs' Maths page, augmentation formulas): with ``M`` the 2x2
image-plane matrix of the operation (x right, **y up**: an image's rows go down,
so a flip of rows is ``diag(1, -1)``) and ``M3 = [[M, 0], [0, 1]]``,

- rotation (``F.rotate``, ``F.affine``'s angle): ``A' = M3 A``;
- mirror (``F.horizontal_flip``, ``F.vertical_flip``): ``A' = M3 A diag(-1, 1, 1)``
  (the head is mirrored too, which keeps ``A'`` a rotation);
- translation, crop, pad and uniform scaling leave ``A`` unchanged (orthographic /
  weak-perspective head-pose labels carry no position or size).

Operations with no exact pose meaning never silently keep the old pose: shear
(``F.affine`` with a non-zero shear), perspective, elastic, a non-constant pad, and a
resize or resized crop that changes the aspect ratio by more than the rounding of the
output size to whole pixels (a squashed face is no rotation of the head; crop a square,
e.g. ``RandomResizedCrop(..., ratio=(1, 1))``). What happens is the pose's
``on_undefined`` policy (``HeadPose(A, on_undefined=...)``, or ``HeadPoseDataset(...,
on_undefined=...)``):

- ``"raise"`` (default): :class:`UndefinedPoseError`;
- ``"drop"``: the pose becomes NaN and ``pose.undefined`` is True (mask it out of the loss);
- ``"keep"``: the pose is kept as it was before the operation and ``pose.undefined`` is True
  (an approximate label, e.g. a 6DRepNet recipe's ``RandomResizedCrop(224, scale=(0.8, 1))``,
  whose aspect change 6DRepNet trains through with the old label).

Once set, ``undefined`` stays True through later operations. Five and ten crops always
raise (one pose cannot follow a tuple of crops). Colour transforms pass ``HeadPose``
through unchanged, as they should.

Landmarks after a mirror
------------------------
A mirror swaps the face's left and right, so landmark *indices* must be permuted
(the left eye corner becomes the right one). ``KeyPoints`` cannot know the
landmark scheme; torchvision's own flips only move the points. Use this module's
:class:`RandomHorizontalFlip` / :class:`RandomVerticalFlip` (drop-in subclasses
with a ``scheme``) which also re-index ``KeyPoints`` whose second-to-last
dimension is the number of landmarks, or apply :class:`PermuteLandmarks` right
after a torchvision flip you applied yourself.

Pixel conventions
-----------------
torchvision flips keypoints as ``x -> W - 1 - x`` (pixel centres at integers, as
:mod:`hpe_cli.geometry.augment`), but rotates and shears them about
``(W / 2, H / 2)``, half a pixel away from the centre the image turns about
(``((W - 1) / 2, (H - 1) / 2)``). The poses do not depend on the centre; keypoints
after ``v2.RandomRotation`` therefore differ from :func:`hpe_cli.augment_batch`'s
by that constant half-pixel rotation offset, ``(I - M) @ (0.5, 0.5)``.

All kernels are batched tensor products on the pose's own device: no host transfers.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torchvision import tv_tensors
from torchvision.transforms import v2
from torchvision.transforms.v2 import functional as F

from ..geometry.landmark_schemes import flip_permutation, scheme_for_count

__all__ = [
    "ON_UNDEFINED",
    "HeadPose",
    "PermuteLandmarks",
    "RandomHorizontalFlip",
    "RandomVerticalFlip",
    "UndefinedPoseError",
    "no_exact_pose",
    "plane_matrix_rotate",
    "pose_mirror",
    "pose_rotate",
]


#: what a kernel does with an operation that is not a rotation of the head (see the module notes)
ON_UNDEFINED = ("raise", "drop", "keep")


class UndefinedPoseError(ValueError):
    """A transform has no exact meaning for a head pose (shear, perspective, elastic, aspect change)."""


def check_policy(on_undefined) -> str:
    """``on_undefined`` validated: one of :data:`ON_UNDEFINED`."""
    if on_undefined not in ON_UNDEFINED:
        raise ValueError(f"expected on_undefined one of {', '.join(map(repr, ON_UNDEFINED))}, got {on_undefined!r}")
    return on_undefined


class HeadPose(tv_tensors.TVTensor):
    """Canonical 300W-LP rotation matrices of the faces of one image (or a batch), shape ``(..., 3, 3)``.

    Parameters
    ----------
    data : array_like, shape (..., 3, 3)
        Canonical matrices ``A`` (x = subject's left, y = up, z = out of the face);
        get them from any system with ``hpe_cli.torch.to_canonical(R, system)`` or
        ``angles_to_canonical(pyr_deg, system)``.
    canvas_size : (int, int), optional
        ``(H, W)`` of the image, as for ``KeyPoints``. Needed by resize / resized
        crop to tell a uniform scaling (pose unchanged) from an aspect change.
    on_undefined : {"raise", "drop", "keep"}
        What an operation with no exact pose meaning does (module notes): raise
        :class:`UndefinedPoseError`, make the pose NaN, or keep it; the latter two set
        ``undefined``.
    undefined : bool
        True once such an operation has run on the pose (``drop`` / ``keep``).
    dtype, device, requires_grad
        As for any TVTensor.

    Examples
    --------
    >>> import torch
    >>> from torchvision.transforms.v2 import functional as F
    >>> from hpe_cli.torch import HeadPose, angles_to_canonical, canonical_to_angles
    >>> pose = HeadPose(angles_to_canonical(torch.tensor([[10.0, 30.0, 5.0]]), "300w_lp"), canvas_size=(64, 64))
    >>> canonical_to_angles(F.horizontal_flip(pose), "300w_lp")[0].round(decimals=4)
    tensor([[ 10., -30.,  -5.]])
    >>> squash = F.resize(HeadPose(pose, on_undefined="drop"), [64, 32])
    >>> squash.undefined, bool(squash.isnan().all())
    (True, True)
    """

    canvas_size: tuple | None
    on_undefined: str
    undefined: bool

    @classmethod
    def _wrap(
        cls, tensor: torch.Tensor, *, canvas_size=None, on_undefined="raise", undefined=False, check_dims: bool = True
    ) -> HeadPose:
        if check_dims and tensor.shape[-2:] != (3, 3):
            raise ValueError(f"expected canonical rotation matrices of shape (..., 3, 3), got {tuple(tensor.shape)}")
        pose = tensor.as_subclass(cls)
        pose.canvas_size = None if canvas_size is None else tuple(int(v) for v in canvas_size)
        pose.on_undefined = on_undefined
        pose.undefined = bool(undefined)
        return pose

    @classmethod
    def wrap(cls, tensor: torch.Tensor, like: HeadPose, **kwargs: Any) -> HeadPose:
        return cls._wrap(
            tensor,
            canvas_size=kwargs.get("canvas_size", like.canvas_size),
            on_undefined=kwargs.get("on_undefined", _policy(like)),
            undefined=kwargs.get("undefined", getattr(like, "undefined", False)),
        )

    def __new__(
        cls,
        data,
        *,
        canvas_size=None,
        on_undefined=None,
        undefined=None,
        dtype=None,
        device=None,  # noqa: PYI034
        requires_grad=None,
    ) -> HeadPose:
        tensor = cls._to_tensor(data, dtype=dtype, device=device, requires_grad=requires_grad)
        if not tensor.is_floating_point():
            tensor = tensor.to(torch.get_default_dtype())
        if canvas_size is None:  # HeadPose(pose) keeps the metadata of a pose
            canvas_size = getattr(data, "canvas_size", None)
        policy = check_policy(on_undefined if on_undefined is not None else _policy(data))
        flag = undefined if undefined is not None else getattr(data, "undefined", False)
        return cls._wrap(tensor, canvas_size=canvas_size, on_undefined=policy, undefined=flag)

    @classmethod
    def _wrap_output(cls, output, args=(), kwargs=None):
        from torch.utils._pytree import tree_flatten

        flat, _ = tree_flatten(args + (tuple(kwargs.values()) if kwargs else ()))
        like = next((x for x in flat if isinstance(x, HeadPose)), None)
        meta = (
            {}
            if like is None
            else {
                "canvas_size": like.canvas_size,
                "on_undefined": _policy(like),
                "undefined": getattr(like, "undefined", False),
            }
        )
        if isinstance(output, torch.Tensor) and not isinstance(output, HeadPose):
            output = HeadPose._wrap(output, check_dims=False, **meta)
        elif isinstance(output, (tuple, list)):
            output = type(output)(HeadPose._wrap(p, check_dims=False, **meta) for p in output)
        return output

    def __repr__(self, *, tensor_contents: Any = None) -> str:
        return self._make_repr(
            canvas_size=self.canvas_size, on_undefined=_policy(self), undefined=getattr(self, "undefined", False)
        )


def _policy(x) -> str:
    return getattr(x, "on_undefined", None) or "raise"


def no_exact_pose(pose, message: str, canvas_size=None):
    """Apply the pose's ``on_undefined`` policy to an operation with no exact pose meaning.

    Raises :class:`UndefinedPoseError` (``"raise"``), or returns the pose as NaN
    (``"drop"``) or unchanged (``"keep"``), marked ``undefined``, on ``canvas_size``
    (default: the pose's own).
    """
    policy = _policy(pose)
    if policy == "raise":
        raise UndefinedPoseError(f"{message} (or set on_undefined='drop' or 'keep' to train through it)")
    raw = _raw(pose)
    data = torch.full_like(raw, float("nan")) if policy == "drop" else raw.clone()
    return HeadPose._wrap(
        data, canvas_size=pose.canvas_size if canvas_size is None else canvas_size, on_undefined=policy, undefined=True
    )


# ------------------------------------------------------------------------------------------ the maths
def _cos_sin_deg(angle_deg: float):
    """cos and sin of a Python float angle, exact at multiples of 90 degrees."""
    r = float(angle_deg) % 360.0
    if r % 90.0 == 0.0:
        return {0: (1.0, 0.0), 1: (0.0, 1.0), 2: (-1.0, 0.0), 3: (0.0, -1.0)}[int(r // 90.0)]
    return math.cos(math.radians(r)), math.sin(math.radians(r))


def plane_matrix_rotate(angle_deg: float):
    """Image-plane matrix (x right, y up) of a counter-clockwise on-screen rotation, as nested lists."""
    c, s = _cos_sin_deg(angle_deg)
    return [[c, -s], [s, c]]


def pose_rotate(A: torch.Tensor, angle_deg: float) -> torch.Tensor:
    """``M3 @ A`` for an image rotated counter-clockwise on screen by ``angle_deg``."""
    c, s = _cos_sin_deg(angle_deg)
    r0, r1 = A[..., 0, :], A[..., 1, :]
    return torch.stack([c * r0 - s * r1, s * r0 + c * r1, A[..., 2, :]], -2)


def pose_mirror(A: torch.Tensor, horizontal: bool) -> torch.Tensor:
    """``M3 @ A @ diag(-1, 1, 1)`` for a horizontal (``diag(-1, 1)``) or vertical (``diag(1, -1)``) flip."""
    # row 0 (hflip) or 1 (vflip) negated by M3, column 0 by diag(-1, 1, 1): built from A, no host data
    r0, r1, r2 = A[..., 0, :], A[..., 1, :], A[..., 2, :]
    rows = [-r0, r1, r2] if horizontal else [r0, -r1, r2]
    out = torch.stack(rows, -2)
    return torch.cat([-out[..., :1], out[..., 1:]], -1)


def _raw(pose):
    return pose.as_subclass(torch.Tensor)


def _dummy_canvas(fn, pose, **kwargs):
    """The new canvas size, from torchvision's own keypoint kernel run on one point (host-side, tiny)."""
    if pose.canvas_size is None:
        return None
    _, size = fn(torch.zeros(1, 2), canvas_size=pose.canvas_size, **kwargs)
    return tuple(size)


# ------------------------------------------------------------------------------------------- kernels
@F.register_kernel(F.horizontal_flip, HeadPose)
def _hflip(pose, *args, **kwargs):
    return tv_tensors.wrap(pose_mirror(_raw(pose), True), like=pose)


@F.register_kernel(F.vertical_flip, HeadPose)
def _vflip(pose, *args, **kwargs):
    return tv_tensors.wrap(pose_mirror(_raw(pose), False), like=pose)


@F.register_kernel(F.rotate, HeadPose)
def _rotate(pose, angle, interpolation=None, expand=False, center=None, fill=None, **kwargs):
    # F.rotate turns the image counter-clockwise on screen by ``angle`` (torchvision's documented sign)
    size = None
    if pose.canvas_size is not None:
        _, size = F.rotate_keypoints(
            torch.zeros(1, 2), canvas_size=pose.canvas_size, angle=angle, expand=expand, center=center
        )
    return tv_tensors.wrap(pose_rotate(_raw(pose), angle), like=pose, canvas_size=size or pose.canvas_size)


def _shear_is_zero(shear) -> bool:
    if shear is None:
        return True
    if isinstance(shear, (int, float)):
        return shear == 0
    return all(float(s) == 0.0 for s in shear)


@F.register_kernel(F.affine, HeadPose)
def _affine(pose, angle, translate=None, scale=1.0, shear=None, interpolation=None, fill=None, center=None, **kw):
    if not _shear_is_zero(shear):
        return no_exact_pose(
            pose,
            f"a sheared face has no exact head pose: expected shear 0 with HeadPose, got "
            f"{shear} (use v2.RandomAffine(..., shear=None))",
        )
    if not float(scale) > 0:
        return no_exact_pose(pose, f"expected a positive affine scale, got {scale}")
    # F.affine's angle is clockwise-positive in its matrix for points (it is F.rotate's angle negated... and
    # F.rotate calls the affine machinery with -angle): on screen, F.affine(angle) turns the image clockwise
    return tv_tensors.wrap(pose_rotate(_raw(pose), -float(angle)), like=pose)


def is_uniform(old, new) -> bool:
    """Whether ``old -> new`` (H, W) is a uniform scaling up to rounding each side to whole pixels."""
    (h0, w0), (h1, w1) = old, new
    lo = max((h1 - 0.5) / h0, (w1 - 0.5) / w0)
    hi = min((h1 + 0.5) / h0, (w1 + 0.5) / w0)
    return lo <= hi + 1e-12


def aspect_message(old, new, what) -> str:
    (h0, w0), (h1, w1) = old, new
    return (
        f"{what} from {w0}x{h0} to {w1}x{h1} changes the aspect ratio (x{w1 / w0:.4g} wide, x{h1 / h0:.4g} "
        "high): a squashed face has no exact head pose; crop a region of the output's aspect ratio first "
        "(e.g. RandomResizedCrop(size, ratio=(1, 1)) for square outputs, or Resize(shorter_side))"
    )


def _scaled(pose, old, new, what):
    """The pose on the new canvas after a scaling ``old -> new`` (H, W): unchanged if uniform, else the policy."""
    if not is_uniform(old, new):
        return no_exact_pose(pose, aspect_message(old, new, what), canvas_size=new)
    return tv_tensors.wrap(_raw(pose).clone(), like=pose, canvas_size=new)


@F.register_kernel(F.resize, HeadPose)
def _resize(pose, size, interpolation=None, max_size=None, antialias=None, **kwargs):
    if pose.canvas_size is None:
        if size is not None and (isinstance(size, int) or len(size) == 1):
            return tv_tensors.wrap(_raw(pose).clone(), like=pose)  # keeps the aspect ratio
        return no_exact_pose(
            pose,
            "resizing to (H, W) needs HeadPose(..., canvas_size=(H, W)) to check that the "
            "aspect ratio is kept, got a HeadPose without canvas_size",
        )
    new = _dummy_canvas(F.resize_keypoints, pose, size=size, max_size=max_size)
    return _scaled(pose, pose.canvas_size, new, "resize")


@F.register_kernel(F.resized_crop, HeadPose)
def _resized_crop(pose, top, left, height, width, size, interpolation=None, antialias=None, **kwargs):
    _, new = F.resized_crop_keypoints(torch.zeros(1, 2), top=top, left=left, height=height, width=width, size=size)
    return _scaled(pose, (height, width), tuple(new), "resized crop")


@F.register_kernel(F.crop, HeadPose)
def _crop(pose, top, left, height, width, **kwargs):
    return tv_tensors.wrap(_raw(pose).clone(), like=pose, canvas_size=(int(height), int(width)))


@F.register_kernel(F.center_crop, HeadPose)
def _center_crop(pose, output_size, **kwargs):
    new = _dummy_canvas(F.center_crop_keypoints, pose, output_size=output_size)
    if new is None:
        h, w = (
            (output_size, output_size)
            if isinstance(output_size, int)
            else ((output_size[0], output_size[0]) if len(output_size) == 1 else output_size)
        )
        new = (int(h), int(w))
    return tv_tensors.wrap(_raw(pose).clone(), like=pose, canvas_size=new)


@F.register_kernel(F.pad, HeadPose)
def _pad(pose, padding, fill=None, padding_mode="constant", **kwargs):
    new = _dummy_canvas(F.pad_keypoints, pose, padding=padding)
    if padding_mode != "constant":
        return no_exact_pose(
            pose,
            f"padding_mode {padding_mode!r} copies mirrored or repeated faces into the "
            "image; expected 'constant' with HeadPose",
            canvas_size=new,
        )
    return tv_tensors.wrap(_raw(pose).clone(), like=pose, canvas_size=new)


def _message(name, why):
    return (
        f"{name} has no exact head-pose meaning ({why}); remove it from a pipeline that carries a HeadPose, "
        "or apply it to the image alone after the geometric steps"
    )


def _undefined(name, why):
    def kernel(pose, *args, **kwargs):  # the canvas keeps its size (perspective, elastic)
        return no_exact_pose(pose, _message(name, why))

    return kernel


def _never(name, why):
    def kernel(pose, *args, **kwargs):
        raise UndefinedPoseError(_message(name, why))

    return kernel


F.register_kernel(F.perspective, HeadPose)(_undefined("perspective", "it is no rotation of the head"))
F.register_kernel(F.elastic, HeadPose)(_undefined("elastic", "it deforms the face"))
F.register_kernel(F.five_crop, HeadPose)(_never("five_crop", "one pose cannot follow five crops"))
F.register_kernel(F.ten_crop, HeadPose)(_never("ten_crop", "one pose cannot follow ten crops"))


# ---------------------------------------------------------------------------- landmark re-indexing
def landmark_flip_permutation(scheme, n):
    """The left/right index permutation of ``n`` landmarks for a mirror under ``scheme``."""

    if isinstance(scheme, str) and scheme == "auto":
        name = scheme_for_count(n)
        if name is None:
            raise ValueError(
                f"a mirror needs a left/right permutation for {n} landmarks: pass scheme= a name "
                "('ibug68', 'face70', 'aflw21') or an index array, got 'auto' and no scheme has "
                f"{n} points"
            )
        return np.asarray(flip_permutation(name))
    return np.asarray(flip_permutation(scheme, n))


class PermuteLandmarks(v2.Transform):
    """Re-index ``KeyPoints`` with a landmark scheme's left/right permutation (``new[i] = old[perm[i]]``).

    Apply it right after a mirror that only moved the points (e.g. torchvision's own
    ``v2.RandomHorizontalFlip`` with ``p=1``). Other inputs pass through.

    Parameters
    ----------
    scheme : "auto", {"ibug68", "face70", "aflw21"} or sequence of int
        ``auto`` picks the scheme by the number of points (68, 70, 21), the size of
        the keypoints' second-to-last dimension.
    """

    _transformed_types = (tv_tensors.KeyPoints,)

    def __init__(self, scheme="auto"):
        super().__init__()
        self.scheme = scheme

    def transform(self, inpt, params):
        if not isinstance(inpt, tv_tensors.KeyPoints) or inpt.ndim < 2:
            return inpt
        perm = torch.tensor(
            landmark_flip_permutation(self.scheme, inpt.shape[-2]), dtype=torch.long, device=inpt.device
        )
        return tv_tensors.wrap(_raw(inpt).index_select(-2, perm), like=inpt)


class _MirrorAware:
    def __init__(self, p: float = 0.5, scheme="auto"):
        super().__init__(p)
        self.scheme = scheme
        self._permute = PermuteLandmarks(scheme)

    def transform(self, inpt, params):
        out = super().transform(inpt, params)
        if isinstance(inpt, tv_tensors.KeyPoints):
            out = self._permute.transform(out, params)
        return out


class RandomHorizontalFlip(_MirrorAware, v2.RandomHorizontalFlip):
    """``v2.RandomHorizontalFlip`` that also re-indexes landmark ``KeyPoints`` (left <-> right) when it flips.

    Parameters
    ----------
    p : float
        Probability of the flip.
    scheme : "auto", {"ibug68", "face70", "aflw21"} or sequence of int
        Landmark permutation (see :class:`PermuteLandmarks`).
    """


class RandomVerticalFlip(_MirrorAware, v2.RandomVerticalFlip):
    """``v2.RandomVerticalFlip`` that also re-indexes landmark ``KeyPoints`` when it flips (see :class:`RandomHorizontalFlip`)."""
