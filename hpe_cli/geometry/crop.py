"""Head crops: enlarged/square boxes, padding outside the frame, landmarks into the crop (pure numpy).

Pixel convention (as everywhere in hpe): pixel ``(u, v)`` has its centre at
integer coordinates, so a box ``[x, x + w)`` covers the pixels whose index is
in that interval. A crop box in *pixel* form is ``(x0, y0, x1, y1)`` integers,
``x1``/``y1`` exclusive, and may reach outside the frame: the part outside is
padded with a constant (:func:`crop_padded`).
"""

from __future__ import annotations

import numpy as np


def check_boxes(boxes) -> np.ndarray:
    """Validate ``(N, 4)`` boxes ``x, y, w, h`` (pixels); returns float64."""
    b = np.asarray(boxes, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 4:
        raise ValueError(f"expected boxes of shape (N, 4), got {b.shape}")
    return b


def expand_boxes(boxes, scale: float = 1.0, square: bool = False) -> np.ndarray:
    """Enlarge boxes about their centre.

    Parameters
    ----------
    boxes : array_like (N, 4)
        ``x, y, w, h`` in pixels.
    scale : float
        Factor on each side length (1 = unchanged, 1.2 = 20 % larger).
    square : bool
        Make each box square first, with side ``max(w, h)``.

    Returns
    -------
    ndarray (N, 4)
        ``x, y, w, h`` of the enlarged boxes (same centres).
    """
    b = check_boxes(boxes)
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"expected a crop scale > 0, got {scale}")
    cx = b[:, 0] + b[:, 2] / 2
    cy = b[:, 1] + b[:, 3] / 2
    w, h = b[:, 2].copy(), b[:, 3].copy()
    if square:
        w = h = np.maximum(w, h)
    w, h = w * scale, h * scale
    return np.stack([cx - w / 2, cy - h / 2, w, h], axis=1)


def pixel_boxes(boxes) -> np.ndarray:
    """Integer crop boxes ``(x0, y0, x1, y1)`` (exclusive ends) of float boxes ``x, y, w, h``.

    ``x0 = round(x)``, ``x1 = x0 + max(1, round(w))``: the crop keeps the box's
    size to the nearest pixel (a square box stays square).
    """
    b = check_boxes(boxes)
    x0 = np.round(b[:, 0]).astype(np.int64)
    y0 = np.round(b[:, 1]).astype(np.int64)
    w = np.maximum(1, np.round(b[:, 2])).astype(np.int64)
    h = np.maximum(1, np.round(b[:, 3])).astype(np.int64)
    return np.stack([x0, y0, x0 + w, y0 + h], axis=1)


def inside_fraction(boxes, width, height) -> np.ndarray:
    """Fraction of each box's area ``x, y, w, h`` inside the image ``[0, width) x [0, height)``."""
    b = check_boxes(boxes)
    ix = np.clip(b[:, 0] + b[:, 2], 0, width) - np.clip(b[:, 0], 0, width)
    iy = np.clip(b[:, 1] + b[:, 3], 0, height) - np.clip(b[:, 1], 0, height)
    area = b[:, 2] * b[:, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(area > 0, np.maximum(ix, 0) * np.maximum(iy, 0) / area, 0.0)


def crop_padded(image: np.ndarray, box, value=0) -> np.ndarray:
    """The pixels of ``image`` in the integer box ``(x0, y0, x1, y1)``, padded with ``value`` outside it.

    Returns an array of shape ``(y1 - y0, x1 - x0) + image.shape[2:]`` (a view
    when the box lies inside the image, else a padded copy).
    """
    x0, y0, x1, y1 = (int(v) for v in box)
    H, W = image.shape[:2]
    if x0 >= 0 and y0 >= 0 and x1 <= W and y1 <= H:
        return image[y0:y1, x0:x1]
    out = np.full((y1 - y0, x1 - x0) + image.shape[2:], value, dtype=image.dtype)
    sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
    if sx1 > sx0 and sy1 > sy0:
        out[sy0 - y0 : sy1 - y0, sx0 - x0 : sx1 - x0] = image[sy0:sy1, sx0:sx1]
    return out


def points_to_crop(points, box, size=None) -> np.ndarray:
    """Map image points into a crop (and its resized image).

    Parameters
    ----------
    points : array_like (N, L, 2)
        ``x, y`` in the frame's pixels (NaN stays NaN).
    box : array_like (N, 4)
        Integer crop boxes ``(x0, y0, x1, y1)``.
    size : (int, int) or None
        ``(width, height)`` the crop is resized to (``cv2.resize`` maps pixel
        centres by ``x' = (x + 0.5) * W' / W - 0.5``); None: no resize.

    Returns
    -------
    ndarray (N, L, 2)
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(box, dtype=np.float64)
    out = p - b[:, None, :2]
    if size is not None:
        sx = size[0] / (b[:, 2] - b[:, 0])
        sy = size[1] / (b[:, 3] - b[:, 1])
        out = np.stack([(out[..., 0] + 0.5) * sx[:, None] - 0.5, (out[..., 1] + 0.5) * sy[:, None] - 0.5], -1)
    return out


def landmark_boxes(points) -> np.ndarray:
    """Tight boxes ``x, y, w, h`` of the finite points of each row of ``(N, L, 2)``; NaN if none."""
    p = np.asarray(points, dtype=np.float64)
    ok = np.isfinite(p).all(-1)
    with np.errstate(invalid="ignore"):
        big = np.where(ok[..., None], p, np.inf).min(1)
        small = np.where(ok[..., None], p, -np.inf).max(1)
    out = np.stack([big[:, 0], big[:, 1], small[:, 0] - big[:, 0], small[:, 1] - big[:, 1]], 1)
    out[~ok.any(1)] = np.nan
    return out


def sixdrepnet_test_boxes(tight, k: float = 0.20) -> np.ndarray:
    """6DRepNet's loose AFLW2000 crop of a tight landmark box (``sixdrepnet/datasets.py``, ``AFLW2000``).

    Sequentially, as that loader does: ``x_min -= 2k|x_max - x_min|``,
    ``y_min -= 2k|y_max - y_min|``, ``x_max += 2k|x_max - x_min|`` (with the
    updated ``x_min``), ``y_max += 0.6k|y_max - y_min|`` (updated ``y_min``).
    Input and output are ``x, y, w, h``.
    """
    b = check_boxes(tight)
    x0, y0 = b[:, 0].copy(), b[:, 1].copy()
    x1, y1 = x0 + b[:, 2], y0 + b[:, 3]
    x0 = x0 - 2 * k * np.abs(x1 - x0)
    y0 = y0 - 2 * k * np.abs(y1 - y0)
    x1 = x1 + 2 * k * np.abs(x1 - x0)
    y1 = y1 + 0.6 * k * np.abs(y1 - y0)
    return np.stack([x0, y0, x1 - x0, y1 - y0], axis=1)
