"""The Python API on arrays of poses (re-exported by :mod:`hpe_cli.api` and :mod:`hpe_cli`): augment, draw, distance.

Each calls the kernels the commands run (``hpe augment``, ``hpe draw``, ``hpe evaluate``).
"""

from __future__ import annotations

import numpy as np

from .geometry.augment import augment_batch as _augment_batch
from .geometry.augment import augment_sample as _a
from .geometry.draw import render_axes
from .geometry.landmark_pose import SCHEME_SIZES, fit_landmark_pose
from .rotation.distances import geodesic_deg
from .rotation.systems import get_system


# ------------------------------------------------------------------------------------------- geometry
def augment_sample(
    pose,
    landmarks=None,
    bbox=None,
    *,
    op,
    angle=None,
    image_size,
    system="300w_lp",
    scheme="auto",
    box_from: str = "auto",
    clip: bool = False,
):
    """One sample's labels, landmarks and box after a flip, rotation or mirror of its image.

    Parameters
    ----------
    pose : array_like, shape (3,) or (3, 3)
        ``(pitch, yaw, roll)`` in degrees, or the stored matrix, of ``system``.
    landmarks : array_like, shape (L, 2), optional
        Pixel coordinates ``(u, v)``, rows going down, pixel centres at integers; NaN = missing.
    bbox : array_like, shape (4,), optional
        ``(x, y, w, h)`` pixels.
    op : {"hflip", "vflip", "hvflip", "rotate", "mirror"} or array_like, shape (2, 2)
        ``rotate``: counter-clockwise on screen by ``angle`` degrees; ``mirror``: about
        the line at ``angle`` degrees; or an orthogonal image-plane matrix (x right, y up).
    angle : float, optional
        Degrees, for ``rotate`` and ``mirror``.
    image_size : (W, H)
        Pixels.
    system : str, path or RotationSystem
        System of ``pose`` and of the result.
    scheme : "auto", str, array_like of int or None
        Landmark left/right permutation applied after a mirror (``auto``: by count, 68/70/21).
    box_from, clip
        See :func:`hpe_cli.geometry.augment.augment_boxes`.

    Returns
    -------
    Augmented
        ``matrix`` (3, 3), ``angles``/``angles_2`` (3,) degrees, ``canonical``,
        ``gimbal_lock``, ``landmarks`` (L, 2) or None, ``bbox`` (4,) or None.

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> out = hpe.augment_sample([10.0, 30.0, 5.0], [[100.0, 50.0]], op="hflip", image_size=(200, 100),
    ...                          scheme=[0])
    >>> out.angles.round(6), out.landmarks
    (array([ 10., -30.,  -5.]), array([[99., 50.]]))
    """

    return _a(
        pose,
        landmarks,
        bbox,
        op=op,
        angle=angle,
        image_size=image_size,
        system=system,
        scheme=scheme,
        box_from=box_from,
        clip=clip,
    )


def augment_batch(
    pose,
    landmarks=None,
    bbox=None,
    *,
    op,
    angle=None,
    image_size,
    system="300w_lp",
    scheme="auto",
    box_from: str = "auto",
    clip: bool = False,
):
    """N samples' labels, landmarks and boxes after flips, rotations or mirrors (vectorised).

    Parameters
    ----------
    pose : array_like, shape (N, 3) or (N, 3, 3)
        ``(pitch, yaw, roll)`` degrees or stored matrices of ``system``.
    landmarks : array_like, shape (N, L, 2), optional
    bbox : array_like, shape (N, 4), optional
    op : str or array_like, shape (2, 2) or (N, 2, 2)
        As in :func:`augment_sample`; one matrix per row allowed.
    angle : float or array_like, shape (N,), optional
        Degrees, one per row allowed.
    image_size : array_like, shape (2,) or (N, 2)
    system, scheme, box_from, clip
        As in :func:`augment_sample`.

    Returns
    -------
    Augmented
        ``matrix`` (N, 3, 3), ``angles``/``angles_2`` (N, 3), ``landmarks`` (N, L, 2), ``bbox`` (N, 4).

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> out = hpe.augment_batch([[20.0, -50.0, 15.0], [0.0, 0.0, 0.0]], op="rotate", angle=[30, 90],
    ...                         image_size=(450, 450))
    >>> out.angles.round(3) + 0.0
    array([[ 43.511, -33.607, -19.343],
           [  0.   ,   0.   , -90.   ]])
    """
    return _augment_batch(
        pose,
        landmarks,
        bbox,
        op=op,
        angle=angle,
        image_size=image_size,
        system=system,
        scheme=scheme,
        box_from=box_from,
        clip=clip,
    )


def draw_axes(image, pose, centre, length=None, *, system="300w_lp", thickness=None):
    """Draw Hopenet-style pose axes (red: subject's left, green: down, blue: nose) onto an image.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint8
        BGR image, drawn on **in place** (copy it first to keep the original).
    pose : array_like, shape (3,), (N, 3), (3, 3) or (N, 3, 3)
        ``(pitch, yaw, roll)`` degrees or stored matrices of ``system``.
    centre : array_like, shape (2,) or (N, 2)
        Head centre ``(u, v)`` in pixels, rows going down.
    length : float, optional
        Line length in pixels (default: a third of the shorter image side).
    system : str, path or RotationSystem
    thickness : int, optional
        Pixels (default from ``length``).

    Returns
    -------
    ndarray
        ``image``.

    Examples
    --------
    >>> import numpy as np, hpe_cli as hpe
    >>> img = hpe.draw_axes(np.zeros((100, 100, 3), np.uint8), [0.0, 0.0, 0.0], (50, 50), 40, thickness=1)
    >>> img[50, 85].argmax(), img[85, 50].argmax()  # red (BGR 2) to the right, green (1) downwards
    (np.int64(2), np.int64(1))
    """

    sysm = get_system(system)
    p = np.asarray(pose, dtype=np.float64)
    R = p.reshape(-1, 3, 3) if p.shape[-2:] == (3, 3) else sysm.from_angles(p.reshape(-1, 3))
    if length is None:
        length = min(image.shape[:2]) / 3.0
    return render_axes(image, sysm.to_canonical(R), np.asarray(centre, dtype=np.float64), length, thickness)


def geodesic(a, b, system=None):
    """The angle of the rotation between two labels, degrees in [0, 180].

    Parameters
    ----------
    a, b : array_like, shape (N, 3) / (3,) angles or (N, 3, 3) / (3, 3) matrices
        Both in the same system. Angles need ``system``; matrices do not (the angle
        is the same in every system, stored active or transposed).
    system : str, path or RotationSystem, optional
        Needed for angle input.

    Returns
    -------
    ndarray, shape (N,) (or () for single rotations)
        ``atan2`` of the skew part's norm and the trace: accurate near 0 and 180 degrees.

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> float(hpe.geodesic([0.0, 30.0, 0.0], [0.0, -60.0, 0.0], system="300w_lp").round(9))
    90.0
    """

    def mat(x):
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-2:] == (3, 3):
            return x
        if system is None:
            raise ValueError(
                "expected matrices of shape (..., 3, 3), or angles with system=, got angles "
                f"of shape {x.shape} and no system"
            )
        return get_system(system).from_angles(x)

    return geodesic_deg(mat(a), mat(b))


def landmark_pose(landmarks, scheme=None, *, system="300w_lp", labels=None):
    """Head rotation from 2-D landmarks alone (the evidence of ``hpe audit --consistency``).

    A weak-perspective fit of DirectMHP's 68-point mean face, batched over all faces
    (:func:`hpe_cli.geometry.landmark_pose.fit_landmark_pose`).

    Parameters
    ----------
    landmarks : array_like, shape (N, L, 2)
        Pixels (x right, y down); NaN or ``(-1, -1)`` marks an invisible point.
    scheme : {"ibug68", "face70", "aflw21"}, optional
        Default: by ``L`` (68, 70, 21).
    system : str, path or RotationSystem
        System of the returned angles and of ``labels``.
    labels : array_like, shape (N, 3), optional
        ``(pitch, yaw, roll)`` degrees in ``system``: also return their angle to the fit.

    Returns
    -------
    dict
        ``angles`` (N, 3) the fit's ``(pitch, yaw, roll)`` in ``system`` (NaN where not
        fitted), ``matrix`` (N, 3, 3) the fit's canonical 300W-LP matrix, ``residual``
        (N,) RMS reprojection error per inter-ocular distance, ``reason`` (N,) why a
        face was not fitted (``""`` when it was); with ``labels`` also ``angle`` (N,)
        degrees between each label and its fit.

    Examples
    --------
    >>> import numpy as np, hpe_cli as hpe
    >>> from hpe_cli.geometry.landmark_pose import project_model
    >>> A = hpe.get_system("300w_lp").to_canonical(hpe.get_system("300w_lp").from_angles([[10.0, -40.0, 5.0]]))
    >>> uv = project_model(A, np.array([100.0]), np.array([[200.0, 220.0]]))  # a noise-free face
    >>> out = hpe.landmark_pose(uv, labels=[[10.0, -40.0, 5.0]])
    >>> out["angles"].round(6).tolist(), bool(out["angle"][0] < 1e-6)
    ([[10.0, -40.0, 5.0]], True)
    """

    uv = np.asarray(landmarks, dtype=np.float64)
    if scheme is None:
        n = uv.shape[1] if uv.ndim == 3 else 0
        scheme = next((k for k, v in SCHEME_SIZES.items() if v == n), None)
        if scheme is None:
            raise ValueError(f"expected 21, 68 or 70 landmarks (aflw21, ibug68, face70), got shape {uv.shape}")
    s = get_system(system)
    fit = fit_landmark_pose(uv, scheme)
    ok = fit["reason"] == ""
    angles = np.full((len(uv), 3), np.nan)
    if ok.any():
        angles[ok] = s.to_angles(s.from_canonical(fit["A"][ok]))[0]
    out = {"angles": angles, "matrix": fit["A"], "residual": fit["residual"], "reason": fit["reason"]}
    if labels is not None:
        out["angle"] = geodesic_deg(s.to_canonical(s.from_angles(np.asarray(labels, dtype=np.float64))), fit["A"])
    return out
