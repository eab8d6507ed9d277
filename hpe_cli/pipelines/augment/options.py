"""``hpe augment``'s settings: one :class:`AugmentOptions`, built by the command line and the Python API alike."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from ...errors import UsageError
from ...geometry.image_ops import BORDERS, INTERPOLATIONS
from ...io.images import IMAGE_COLUMNS  # noqa: F401  (the columns tried for the image name, as draw's)
from ...io.table_source import DEFAULT_BATCH
from ..renamed import take_renamed

#: rows whose angles and r00..r22 disagree by more than this (Frobenius) are rejected
AGREE_TOL = 1e-3
#: the operations: mirrors and turns of the image plane, a crop, a resize
OPS = ("hflip", "vflip", "hvflip", "rotate", "mirror", "crop", "scale")
SCHEMES = ("auto", "ibug68", "face70", "aflw21", "none")
BOX_FROM = ("auto", "landmarks", "corners")


def describe_op(op: str, angle=None, crop=None, scale=None) -> str:
    """The operation as the summary and the ``hpe:augment`` metadata name it (``"rotate 30 deg counter-clockwise"``)."""
    if op == "hvflip":
        return "hflip+vflip (rotation by 180)"
    if op in ("hflip", "vflip"):
        return op
    if op == "rotate":
        return f"rotate {angle:g} deg counter-clockwise"
    if op == "crop":
        return f"crop {crop[2]}x{crop[3]} at ({crop[0]}, {crop[1]})"
    if op == "scale":
        return f"scale by {scale:g}"
    return f"mirror about the {angle:g} deg line"


@dataclass(frozen=True)
class AugmentOptions:
    """The settings of one ``hpe augment`` run (its options, by the same names).

    Attributes
    ----------
    op : str
        One of :data:`OPS`: ``hflip``, ``vflip``, ``hvflip`` (both: a turn by 180), ``rotate`` (``angle`` degrees
        counter-clockwise on screen), ``mirror`` (about the line at ``angle`` degrees from the horizontal),
        ``crop`` (``crop = (x, y, w, h)``, whole pixels, w, h >= 1), ``scale`` (``scale > 0``).
    angle : float, optional
        Degrees, finite; for ``rotate`` and ``mirror`` only.
    crop : tuple of 4 int, optional
        ``(x, y, w, h)`` in pixels: the rectangle whose top-left pixel is ``(x, y)``.
    scale : float, optional
        Resize factor, > 0.
    image_size : tuple of 2 int, optional
        ``(W, H)`` in pixels, checked against ``image_width/image_height`` and the images.
    system : str, path or RotationSystem, optional
        ``--system``: the labels' and the output's system (None: the file's own, else ``300w_lp``).
    radians : bool
        Input angles in radians.
    scheme : str
        Landmark left/right scheme (``auto`` by count, ``ibug68``, ``face70``, ``aflw21``, ``none``).
    box_from, clip
        How the new box is made (``auto``, ``landmarks``, ``corners``) and whether it is clipped to the image.
    images_dir, out_images, image_column
        The input images' folder, the folder for the transformed images, the column naming each row's image.
    images_optional : bool
        ``images_dir`` is a ``.mat`` folder's own (not given by the user): a missing image is no reject.
    interpolation, border, jpeg_quality
        Resampling (:data:`~hpe_cli.geometry.image_ops.INTERPOLATIONS`), fill
        (:data:`~hpe_cli.geometry.image_ops.BORDERS`), JPEG quality 1..100.
    rejects, strict, overwrite
        ``--rejects FILE``, ``--strict``, ``--overwrite``.
    batch_size : int
        Rows per batch (>= 1).
    threads : int, optional
        Threads transforming batches, >= 1 (``--threads``); None: one per core, at most 8
        (:func:`hpe_cli.pipelines.pools.default_threads`). The output does not depend on it.
    verbose : int
        ``-v`` count.
    workers : int, optional
        Deprecated spelling of ``threads`` (a ``DeprecationWarning``; ``--workers`` is for processes).
    """

    op: str
    angle: float | None = None
    crop: tuple | None = None
    scale: float | None = None
    image_size: tuple | None = None
    system: object = None
    radians: bool = False
    scheme: str = "auto"
    box_from: str = "auto"
    clip: bool = False
    images_dir: object = None
    out_images: object = None
    image_column: str | None = None
    images_optional: bool = False
    interpolation: str = "linear"
    border: str = "constant"
    jpeg_quality: int = 95
    rejects: object = None
    strict: bool = False
    overwrite: bool = False
    batch_size: int = DEFAULT_BATCH
    threads: int | None = None
    verbose: int = 0
    workers: int | None = None

    def __post_init__(self):
        take_renamed(self, "workers", "threads")
        if self.threads is not None and not (
            isinstance(self.threads, int) and not isinstance(self.threads, bool) and self.threads >= 1
        ):
            raise UsageError(f"threads: expected an integer >= 1 or None, got {self.threads!r}")
        for name, value, allowed in (
            ("op", self.op, OPS),
            ("scheme", self.scheme, SCHEMES),
            ("box_from", self.box_from, BOX_FROM),
            ("interpolation", self.interpolation, INTERPOLATIONS),
            ("border", self.border, BORDERS),
        ):
            if value not in allowed:
                raise UsageError(f"{name}: expected one of {', '.join(allowed)}, got {value!r}")
        if (self.angle is not None) != (self.op in ("rotate", "mirror")):
            raise UsageError(f"angle: expected a number for rotate and mirror only, got {self.angle!r} for {self.op}")
        if self.angle is not None and not math.isfinite(self.angle):
            raise UsageError(f"angle: expected a finite angle in degrees, got {self.angle}")
        if (self.crop is not None) != (self.op == "crop"):
            raise UsageError(f"crop: expected (x, y, w, h) for crop only, got {self.crop!r} for {self.op}")
        if self.crop is not None and (
            len(self.crop) != 4 or any(v != int(v) for v in self.crop) or self.crop[2] < 1 or self.crop[3] < 1
        ):
            raise UsageError(f"crop: expected 4 whole pixels x, y, w, h with w, h >= 1, got {self.crop!r}")
        if (self.scale is not None) != (self.op == "scale"):
            raise UsageError(f"scale: expected a factor for scale only, got {self.scale!r} for {self.op}")
        if self.scale is not None and self.scale <= 0:  # as --scale's range (NaN: every row is rejected)
            raise UsageError(f"scale: expected a factor > 0, got {self.scale}")
        if self.image_size is not None and (len(self.image_size) != 2 or min(self.image_size) < 1):
            raise UsageError(f"image_size: expected (W, H) in pixels >= 1, got {self.image_size!r}")
        if not 1 <= self.jpeg_quality <= 100:
            raise UsageError(f"jpeg_quality: expected 1..100, got {self.jpeg_quality}")
        if self.batch_size < 1:
            raise UsageError(f"batch_size: expected >= 1, got {self.batch_size}")

    @property
    def description(self) -> str:
        """The operation in words (:func:`describe_op`)."""
        return describe_op(self.op, self.angle, self.crop, self.scale)


def for_input(input, opts: AugmentOptions) -> AugmentOptions:
    """``opts`` completed for ``input``: a ``.mat`` folder holds its images, so without ``images_dir`` (and
    ``image_column``) they give the rows' sizes and, with ``out_images``, are the pictures transformed.

    Raises
    ------
    UsageError
        ``out_images`` without ``images_dir`` for a table (its images are elsewhere).
    """
    if opts.images_dir is not None:
        return opts
    folder = Path(input).is_dir()
    if opts.out_images is not None and not folder:
        raise UsageError("--out-images needs --images (the folder of the input images)")
    if folder and opts.image_column is None:
        return replace(opts, images_dir=input, images_optional=opts.out_images is None)
    return opts
