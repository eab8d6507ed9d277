"""Line-of-sight ("crop") labels: the head as a camera looking straight at it sees it (SPEC §10).

A label made with a camera's rotation describes the head relative to the
camera's optical axis. A network that only sees a crop around the head sees
it along the ray from the camera centre through the head centre. With ``c``
the head centre in OpenCV camera coordinates and ``Q`` the smallest rotation
taking the optical axis ``(0, 0, 1)`` to ``c / |c|`` (axis ``z x c``), a
virtual camera at the same centre whose optical axis is that ray sees the
head rotated by ``Q.T @ cam_R @ R_head``; the 300W-LP label is then

    A' = E @ Q.T @ cam_R @ R_head = (E @ Q.T @ E) @ A,    E = diag(1, -1, -1).

The angle of ``Q`` (the angle between the optical axis and the ray) is the
``ray_angle``. opentrack's ``perspective_corrected_rotation`` (used by
neuralnet-tracker-traincode's ``scripts/dsprocess_panoptic.py``) makes the
same correction. Pure numpy.
"""

from __future__ import annotations

import numpy as np

E = np.diag([1.0, -1.0, -1.0])


def ray_rotation(centre) -> tuple:
    """The smallest rotation taking ``(0, 0, 1)`` to the ray through ``centre``.

    Parameters
    ----------
    centre : array_like, shape (N, 3)
        Points in OpenCV camera coordinates (``z > 0`` in front of the camera).

    Returns
    -------
    Q : ndarray, shape (N, 3, 3)
        Proper rotations with ``Q @ (0, 0, 1) = c / |c|``; the identity for a
        point on the axis; NaN where ``c`` is zero or not finite. A point
        exactly behind the camera (``c`` along ``-z``) gets the half turn about x.
    angle : ndarray, shape (N,)
        Rotation angle of ``Q`` in degrees, in [0, 180].

    Notes
    -----
    Rodrigues' formula with axis ``k = z x d`` (``d = c / |c|``), written
    without dividing by ``|k|``: ``Q = I + [k]x + [k]x^2 / (1 + d_z)``.
    """
    c = np.asarray(centre, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"expected centre of shape (N, 3), got {c.shape}")
    with np.errstate(invalid="ignore", divide="ignore"):
        d = c / np.linalg.norm(c, axis=1, keepdims=True)
        x, y, z = d[:, 0], d[:, 1], d[:, 2]
        # k = (0, 0, 1) x d = (-y, x, 0); [k]x^2 / (1 + z) written out
        f = 1.0 / (1.0 + z)
        Q = np.empty((len(c), 3, 3))
        Q[:, 0, 0] = 1.0 - x * x * f
        Q[:, 0, 1] = -x * y * f
        Q[:, 0, 2] = x
        Q[:, 1, 0] = -x * y * f
        Q[:, 1, 1] = 1.0 - y * y * f
        Q[:, 1, 2] = y
        Q[:, 2, 0] = -x
        Q[:, 2, 1] = -y
        Q[:, 2, 2] = z
    back = np.isclose(z, -1.0, atol=1e-12) & np.isfinite(z)
    Q[back] = np.diag([1.0, -1.0, -1.0])
    angle = np.rad2deg(np.arctan2(np.hypot(x, y), z))
    return Q, angle


def camera_to_crop_labels(A, centre) -> tuple:
    """Turn camera-frame 300W-LP label matrices into line-of-sight labels.

    Parameters
    ----------
    A : array_like, shape (N, 3, 3)
        Camera-frame labels ``E @ cam_R @ R_head`` (canonical 300W-LP matrices).
    centre : array_like, shape (N, 3)
        Head centres in the same camera's OpenCV coordinates.

    Returns
    -------
    A_crop : ndarray, shape (N, 3, 3)
        ``(E @ Q.T @ E) @ A``: the label a camera looking straight at the head sees.
    ray_angle : ndarray, shape (N,)
        Angle between the optical axis and the ray to the head centre, degrees.
    """
    Q, angle = ray_rotation(centre)
    A = np.asarray(A, dtype=np.float64)
    return E @ np.swapaxes(Q, -1, -2) @ E @ A, angle


__all__ = ["ray_rotation", "camera_to_crop_labels"]
