"""Image warps that match :mod:`hpe_cli.geometry.augment` to the pixel.

The landmark maths puts pixel centres at integer coordinates and turns about
``((W - 1) / 2, (H - 1) / 2)``; ``cv2.warpAffine`` uses the same pixel
coordinates, so warping with :func:`~hpe_cli.geometry.augment.pixel_affine`
moves image content exactly where the landmarks go. The three flips use
``cv2.flip`` (no interpolation); the output keeps the input's size, so corners
of a rotated image are cut and filled with the border value.
"""

from __future__ import annotations

import numpy as np

from .augment import check_plane, pixel_affine

INTERPOLATIONS = ("linear", "cubic", "nearest", "area", "lanczos")
BORDERS = ("constant", "replicate", "reflect", "reflect101", "wrap")

_FLIP_CODES = {(-1.0, 1.0): 1, (1.0, -1.0): 0, (-1.0, -1.0): -1}


def cv_flags() -> tuple[dict, dict]:
    """OpenCV's flags by hpe's names: ``(interpolation name -> cv2.INTER_*, border name -> cv2.BORDER_*)``
    (the names of :data:`INTERPOLATIONS` and :data:`BORDERS`)."""
    import cv2

    interp = {
        "linear": cv2.INTER_LINEAR,
        "cubic": cv2.INTER_CUBIC,
        "nearest": cv2.INTER_NEAREST,
        "area": cv2.INTER_AREA,
        "lanczos": cv2.INTER_LANCZOS4,
    }
    border = {
        "constant": cv2.BORDER_CONSTANT,
        "replicate": cv2.BORDER_REPLICATE,
        "reflect": cv2.BORDER_REFLECT,
        "reflect101": cv2.BORDER_REFLECT_101,
        "wrap": cv2.BORDER_WRAP,
    }
    return interp, border


def warp_image(image, M, interpolation: str = "linear", border: str = "constant", border_value=0) -> np.ndarray:
    """Apply one image-plane augmentation to an image.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Any dtype OpenCV accepts (uint8, uint16, float32, ...).
    M : array_like, shape (2, 2)
        Image-plane matrix (x right, y up) from
        :func:`~hpe_cli.geometry.augment.plane_matrix`.
    interpolation : {"linear", "cubic", "nearest", "area", "lanczos"}
        Ignored by the exact flips.
    border : {"constant", "replicate", "reflect", "reflect101", "wrap"}
        How pixels that come from outside the input are filled.
    border_value : scalar or sequence
        Fill value for ``border="constant"``.

    Returns
    -------
    ndarray
        Same shape and dtype as ``image``.
    """
    import cv2

    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.shape[0] == 0 or img.shape[1] == 0:
        raise ValueError(f"expected an image of shape (H, W) or (H, W, C), got {img.shape}")
    M, _ = check_plane(M)
    if M.shape != (2, 2):
        raise ValueError(f"expected one (2, 2) image-plane matrix, got {M.shape}")
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"expected interpolation in {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
    if border not in BORDERS:
        raise ValueError(f"expected border in {', '.join(BORDERS)}, got {border!r}")
    h, w = img.shape[:2]
    if M[0, 1] == 0 and M[1, 0] == 0:
        key = (float(M[0, 0]), float(M[1, 1]))
        if key == (1.0, 1.0):
            return img.copy()
        return cv2.flip(img, _FLIP_CODES[key])
    interp, borders = cv_flags()
    if np.ndim(border_value) == 0:
        border_value = (float(border_value),) * 4
    P = pixel_affine(M, (w, h))
    return cv2.warpAffine(
        img, P, (w, h), flags=interp[interpolation], borderMode=borders[border], borderValue=tuple(border_value)
    )


def opencv_rotation_matrix(phi_deg: float, image_size) -> np.ndarray:
    """OpenCV's own ``getRotationMatrix2D`` about the pixel-centre image centre.

    The reference that :func:`~hpe_cli.geometry.augment.pixel_affine` must equal
    for ``rotate``; ``image_size`` is ``(W, H)``.
    """
    import cv2

    w, h = image_size
    return cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), float(phi_deg), 1.0)
