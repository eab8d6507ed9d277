"""Pinhole projection with OpenCV's 5-coefficient lens distortion, batched.

A world point ``X`` goes to the camera frame as ``Xc = R @ X + t`` (OpenCV's
frame: x right, y down, z forward), to normalised coordinates
``x = Xc[0] / Xc[2]``, ``y = Xc[1] / Xc[2]``, is distorted with
``dist = (k1, k2, p1, p2, k3)``::

    r2 = x^2 + y^2,  f = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    xd = x f + 2 p1 x y + p2 (r2 + 2 x^2)
    yd = y f + p1 (r2 + 2 y^2) + 2 p2 x y

and mapped to pixels with ``K``: ``u = fx xd + skew yd + cx``, ``v = fy yd + cy``.
This is ``cv2.projectPoints``, which differs only in ignoring a skew
``K[0, 1]`` (0 in every Panoptic calibration). The panoptic-toolbox ``projectPoints`` that
WHENet and DirectMHP copy overwrites ``x`` with ``xd`` before it computes
``yd`` (SPEC §6); :func:`project_points_panoptic_toolbox` keeps that bug for
comparisons only.
"""

from __future__ import annotations

import numpy as np


def _split(X, K, dist, R, t):
    X = np.asarray(X, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if X.shape[-1:] != (3,):
        raise ValueError(f"expected points of shape (..., 3), got {X.shape}")
    if K.shape[-2:] != (3, 3) or R.shape[-2:] != (3, 3):
        raise ValueError(f"expected K and R of shape (..., 3, 3), got {K.shape} and {R.shape}")
    t = t.reshape(t.shape[:-2] + (3,)) if t.shape[-2:] == (3, 1) else t
    if t.shape[-1:] != (3,):
        raise ValueError(f"expected t of shape (..., 3), got {t.shape}")
    if dist.shape[-1] < 5:  # OpenCV accepts 4 coefficients (k3 = 0)
        dist = np.concatenate([dist, np.zeros(dist.shape[:-1] + (5 - dist.shape[-1],))], axis=-1)
    return camera_points(X, R, t), K, dist


def camera_points(X, R, t) -> np.ndarray:
    """``R @ X + t`` for points ``X`` (..., 3); ``R`` (..., 3, 3), ``t`` (..., 3).

    Written out per component: numpy's batched ``matmul`` of many 3x3 by 3x1
    products is an order of magnitude slower than these broadcast products.
    """
    X = np.asarray(X, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    x0, x1, x2 = X[..., 0], X[..., 1], X[..., 2]
    return np.stack([R[..., i, 0] * x0 + R[..., i, 1] * x1 + R[..., i, 2] * x2 + t[..., i] for i in range(3)], axis=-1)


def distort(x, y, dist):
    """Apply OpenCV's ``(k1, k2, p1, p2, k3)`` model to normalised coordinates."""
    k1, k2, p1, p2, k3 = (dist[..., i] for i in range(5))
    r2 = x * x + y * y
    f = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * f + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * f + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def project_points(X, K, dist, R, t):
    """Project world points into a camera (OpenCV's model, correct).

    Parameters
    ----------
    X : array_like, shape (..., 3)
        World points (any length unit, the same as ``t``).
    K : array_like, shape (..., 3, 3)
        Intrinsics in pixels.
    dist : array_like, shape (..., 5)
        ``k1, k2, p1, p2, k3`` (4 values mean ``k3 = 0``).
    R : array_like, shape (..., 3, 3)
        World-to-camera rotation.
    t : array_like, shape (..., 3) or (..., 3, 1)
        World-to-camera translation.

    The leading dimensions of ``K``, ``dist``, ``R`` and ``t`` broadcast
    against ``X.shape[:-1]``: one camera for all points (``K`` (3, 3)), or,
    for ``X`` of shape (N, C, M, 3), cameras of shape (C, 1, 3, 3).

    Returns
    -------
    uv : ndarray, shape (..., 2)
        Pixel coordinates (OpenCV convention: pixel centres at integers).
    z : ndarray, shape (...)
        Depth along the optical axis, in the unit of ``X``. Points with
        ``z <= 0`` are behind the camera; their ``uv`` is meaningless.
    """
    Xc, K, dist = _split(X, K, dist, R, t)
    z = Xc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = Xc[..., 0] / z
        y = Xc[..., 1] / z
    xd, yd = distort(x, y, dist)
    u = K[..., 0, 0] * xd + K[..., 0, 1] * yd + K[..., 0, 2]
    v = K[..., 1, 1] * yd + K[..., 1, 2]
    return np.stack([u, v], axis=-1), z


def project_points_panoptic_toolbox(X, K, dist, R, t):
    """The panoptic-toolbox projection with its distortion bug, for comparison only.

    Same arguments and returns as :func:`project_points`, but ``y`` is
    distorted with the already-distorted ``x`` (as in WHENet's and
    DirectMHP's copies). The error is ``2 p2 y (x_d - x)`` in normalised
    coordinates: up to 0.07 pixel inside the image on 160906_pizza1's HD
    cameras (their ``p2`` is about 1e-3), more on lenses with larger
    tangential distortion or outside the image.
    """
    Xc, K, dist = _split(X, K, dist, R, t)
    k1, k2, p1, p2, k3 = (dist[..., i] for i in range(5))
    z = Xc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = Xc[..., 0] / z
        y = Xc[..., 1] / z
    r2 = x * x + y * y
    f = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2**3
    x = x * f + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    y = y * f + 2.0 * p2 * x * y + p1 * (r2 + 2.0 * y * y)
    u = K[..., 0, 0] * x + K[..., 0, 1] * y + K[..., 0, 2]
    v = K[..., 1, 1] * y + K[..., 1, 2]
    return np.stack([u, v], axis=-1), z


def max_valid_r2(dist, r2_cap: float = 4.0, samples: int = 4001) -> np.ndarray:
    """Largest normalised ``r^2`` up to which the radial model stays monotonic.

    Beyond the first turning point of ``r * f(r^2)`` the polynomial folds back
    and a point far outside the field of view can land inside the image. The
    calibration was fitted inside the image, so anything beyond is outside it.

    Parameters
    ----------
    dist : array_like, shape (..., 5)
    r2_cap : float
        Upper bound returned when the model is monotonic up to ``r2_cap``
        (4 is 63 degrees off the optical axis).

    Returns
    -------
    ndarray, shape (...)
    """
    dist = np.asarray(dist, dtype=np.float64)
    k1, k2, k3 = dist[..., 0, None], dist[..., 1, None], dist[..., 4, None]
    r2 = np.linspace(0.0, r2_cap, samples)
    # d/dr [r f(r^2)] = 1 + 3 k1 r2 + 5 k2 r2^2 + 7 k3 r2^3
    slope = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
    bad = slope <= 0
    first = np.where(bad.any(-1), bad.argmax(-1), samples)
    return np.where(first < samples, r2[np.minimum(first, samples - 1)], r2_cap)
