"""Head-pose labels, landmarks and boxes under 2-D image rotations and mirrors (SPEC §5).

Every geometric augmentation handled here is an isometry of the image plane
that fixes the image centre, written as a 2x2 orthogonal matrix ``M`` in the
canonical frame's image plane (x = image right, **y = up**):

- rotate the image counter-clockwise on screen by ``phi`` degrees (OpenCV's
  ``getRotationMatrix2D`` angle): ``M = [[cos phi, -sin phi], [sin phi, cos phi]]``;
- mirror about the line through the centre at ``theta`` degrees from the image's
  horizontal axis (counter-clockwise, y up):
  ``M = [[cos 2theta, sin 2theta], [sin 2theta, -cos 2theta]]``; ``hflip`` is
  ``theta = 90`` (``diag(-1, 1)``), ``vflip`` is ``theta = 0`` (``diag(1, -1)``),
  and ``hvflip`` (both) is the rotation by 180 (``diag(-1, -1)``).

The canonical 300W-LP label ``A`` becomes ``A' = M3 @ A`` for a rotation and
``A' = M3 @ A @ S`` for a mirror, with ``M3 = [[M, 0], [0, 1]]`` and
``S = diag(-1, 1, 1)``: the right-hand ``S`` mirrors the (assumed symmetric)
head itself, which keeps ``A'`` a proper rotation. After a mirror the landmarks
are re-indexed with the scheme's left/right permutation.

Pixel convention
----------------
Image coordinates are ``(u, v)`` = (column, row), rows going down, and pixel
``(u, v)`` has its **centre at integer coordinates** (OpenCV's convention for
``warpAffine``/``flip``). The image therefore spans ``[-0.5, W - 0.5]`` and its
centre is ``((W - 1) / 2, (H - 1) / 2)``: ``hflip`` maps ``u -> W - 1 - u``,
exactly what ``cv2.flip`` does to pixel columns, and ``rotate`` turns about that
centre, which is ``cv2.getRotationMatrix2D(((W-1)/2, (H-1)/2), phi, 1)``. Boxes
``(x, y, w, h)`` are read in the same coordinates: corners ``(x, y)`` and
``(x + w, y + h)``. Using ``(W/2, H/2)`` instead (a common habit) puts the
moved points up to 1.4 px (exactly 1 px for a flip) away from where the warped
image shows them.

Everything is vectorised: leading dimensions broadcast (one op for all rows,
or one matrix per row).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotation import canonical_to_labels, get_system
from .landmark_schemes import flip_permutation, scheme_for_count

#: operation names accepted by :func:`plane_matrix`
OPS = ("hflip", "vflip", "hvflip", "rotate", "mirror")
#: how a new box is made: see :func:`augment_boxes`
BOX_FROM = ("auto", "landmarks", "corners")


def _cos_sin_deg(deg):
    """cos and sin of degrees, exact (0, +-1) at multiples of 90 so flips stay exact."""
    deg = np.asarray(deg, dtype=np.float64)
    r = np.mod(deg, 360.0)
    c, s = np.cos(np.deg2rad(r)), np.sin(np.deg2rad(r))
    q = r / 90.0
    k = np.round(q)
    exact = np.isfinite(q) & (q == k)
    k = np.where(exact, k, 0).astype(np.intp) % 4
    c = np.where(exact, np.array([1.0, 0.0, -1.0, 0.0])[k], c)
    s = np.where(exact, np.array([0.0, 1.0, 0.0, -1.0])[k], s)
    return c, s


def plane_matrix(op: str, angle=None) -> np.ndarray:
    """The image-plane matrix ``M`` (x right, y up) of an augmentation.

    Parameters
    ----------
    op : {"hflip", "vflip", "hvflip", "rotate", "mirror"}
        ``rotate``: counter-clockwise on screen by ``angle`` degrees (OpenCV's
        sign). ``mirror``: about the line through the image centre at ``angle``
        degrees counter-clockwise from the horizontal axis (90 = ``hflip``,
        0 = ``vflip``). ``hvflip``: both flips (a rotation by 180).
    angle : float or array_like, optional
        Degrees, any real value; required for ``rotate`` and ``mirror``. An array
        gives one matrix per entry.

    Returns
    -------
    ndarray, shape ``angle.shape + (2, 2)`` (or (2, 2) for flips)
        Orthogonal; ``det = -1`` for mirrors.
    """
    if op in ("hflip", "vflip", "hvflip"):
        if angle is not None:
            raise ValueError(f"op {op!r} takes no angle, got {angle!r}")
        return {"hflip": np.diag([-1.0, 1.0]), "vflip": np.diag([1.0, -1.0]), "hvflip": np.diag([-1.0, -1.0])}[op]
    if op not in OPS:
        raise ValueError(f"expected op in {', '.join(OPS)}, got {op!r}")
    if angle is None:
        raise ValueError(f"op {op!r} needs an angle in degrees")
    a = np.asarray(angle, dtype=np.float64)
    if not np.isfinite(a).all():
        raise ValueError(f"expected finite angles in degrees, got {angle!r}")
    if op == "rotate":
        c, s = _cos_sin_deg(a)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    c, s = _cos_sin_deg(2.0 * a)
    return np.stack([np.stack([c, s], -1), np.stack([s, -c], -1)], -2)


def check_plane(M) -> tuple[np.ndarray, np.ndarray]:
    """``(M, det M)``: ``M`` (..., 2, 2) as float64, checked to be finite orthogonal image-plane matrices.

    Raises
    ------
    ValueError
        Expected shape (..., 2, 2) and ``|M M^T - I| <= 1e-9`` (rotations or mirrors, no scaling).
    """
    M = np.asarray(M, dtype=np.float64)
    if M.shape[-2:] != (2, 2):
        raise ValueError(f"expected image-plane matrices of shape (..., 2, 2), got {M.shape}")
    err = np.abs(M @ np.swapaxes(M, -1, -2) - np.eye(2)).max(initial=0.0)
    if not np.isfinite(M).all() or err > 1e-9:
        raise ValueError(
            f"expected orthogonal image-plane matrices (rotations or mirrors, no scaling), got |M M^T - I| = {err:.3g}"
        )
    det = M[..., 0, 0] * M[..., 1, 1] - M[..., 0, 1] * M[..., 1, 0]
    return M, det


def is_mirror(M) -> np.ndarray:
    """True where ``M`` reverses orientation (``det M = -1``): landmarks must be re-indexed."""
    return check_plane(M)[1] < 0


def augment_canonical(A, M) -> np.ndarray:
    """The canonical 300W-LP label after the image augmentation ``M`` (SPEC §5).

    Parameters
    ----------
    A : array_like, shape (..., 3, 3)
        Canonical (300W-LP) active rotation matrices.
    M : array_like, shape (..., 2, 2)
        Image-plane matrices from :func:`plane_matrix` (x right, y up); broadcast
        against ``A``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``M3 @ A`` for rotations, ``M3 @ A @ diag(-1, 1, 1)`` for mirrors; a
        proper rotation in both cases.
    """
    M, det = check_plane(M)
    return _canonical(np.asarray(A, dtype=np.float64), M, det)


def _canonical(A, M, det):
    M3 = np.zeros(M.shape[:-2] + (3, 3))
    M3[..., :2, :2] = M
    M3[..., 2, 2] = 1.0
    out = M3 @ A
    # right-multiplying by S negates column 0: the head's own left/right mirror
    sign = np.where(det < 0, -1.0, 1.0)[..., None]
    out[..., :, 0] *= np.broadcast_to(sign, out.shape[:-1])
    return out


def _image_size(image_size) -> np.ndarray:
    wh = np.asarray(image_size, dtype=np.float64)
    if wh.shape[-1:] != (2,):
        raise ValueError(f"expected image_size (W, H) of shape (..., 2), got {wh.shape}")
    if not (np.isfinite(wh).all() and (wh > 0).all()):
        raise ValueError(f"expected positive image sizes (W, H) in pixels, got {image_size!r}")
    return wh


def pixel_affine(M, image_size) -> np.ndarray:
    """The forward 2x3 affine in pixel coordinates (u right, v down, centres at integers).

    ``[u', v'] = P @ [u, v, 1]``; this is the matrix ``cv2.warpAffine`` takes
    (without ``WARP_INVERSE_MAP``). For ``rotate`` it equals
    ``cv2.getRotationMatrix2D(((W-1)/2, (H-1)/2), phi, 1)``.

    Parameters
    ----------
    M : array_like, shape (..., 2, 2)
        Image-plane matrices (x right, y up).
    image_size : array_like, shape (..., 2)
        ``(W, H)`` in pixels.

    Returns
    -------
    ndarray, shape (..., 2, 3)
    """
    M, _ = check_plane(M)
    return plane_to_pixel(M, _image_size(image_size))


def plane_to_pixel(M, wh):
    """:func:`pixel_affine` without its checks: ``M`` (..., 2, 2) already a plane matrix, ``wh`` (..., 2) any
    finite sizes in pixels (a pipeline passes rows it will reject too).

    Returns
    -------
    ndarray, shape (..., 2, 3)
        The forward pixel affine ``[u', v'] = P @ [u, v, 1]``.
    """
    # conjugate by diag(1, -1): the y-up plane to rows-down pixels
    N = M * np.array([[1.0, -1.0], [-1.0, 1.0]]) + 0.0  # + 0.0 drops negative zeros
    c = (wh - 1.0) / 2.0
    t = c - (N @ c[..., None])[..., 0]
    lead = np.broadcast_shapes(N.shape[:-2], t.shape[:-1])
    N = np.broadcast_to(N, lead + (2, 2))
    t = np.broadcast_to(t, lead + (2,))
    return np.concatenate([N, t[..., None]], axis=-1)


def crop_affine(x, y) -> np.ndarray:
    """The pixel affine (2, 3) of a crop whose top-left pixel is ``(x, y)`` of the input: ``u' = u - x``.

    A crop only moves the origin: the head's rotation is unchanged (the 300W-LP model is orthographic), and
    points, boxes and ``tdx, tdy`` shift by ``(-x, -y)``. ``cv2.warpAffine`` with this matrix (or slicing, for
    integer ``x, y`` inside the image) gives the cropped image.
    """
    x, y = float(x), float(y)
    if not (np.isfinite(x) and np.isfinite(y)):
        raise ValueError(f"expected a finite crop origin, got ({x}, {y})")
    return np.array([[1.0, 0.0, -x], [0.0, 1.0, -y]])


def scale_affine(sx, sy=None) -> np.ndarray:
    """The pixel affine (2, 3) of a resize by ``sx`` (and ``sy``, default ``sx``) with pixel centres at integers:
    ``u' = (u + 0.5) * sx - 0.5``, the mapping ``cv2.resize`` uses (image edges stay image edges)."""
    sx = float(sx)
    sy = sx if sy is None else float(sy)
    if not (np.isfinite(sx) and np.isfinite(sy) and sx > 0 and sy > 0):
        raise ValueError(f"expected positive finite scale factors, got ({sx}, {sy})")
    return np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5]])


def move_point(u, v, P) -> tuple:
    """One point per row ``(u, v)`` (each shape (N,)) moved by pixel affines ``P`` (N, 2, 3) or (2, 3)."""
    P = np.asarray(P, dtype=np.float64)
    u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    return (P[..., 0, 0] * u + P[..., 0, 1] * v + P[..., 0, 2], P[..., 1, 0] * u + P[..., 1, 1] * v + P[..., 1, 2])


def move_td(tdx, tdy, P, h_in, h_out, from_bottom) -> tuple:
    """Move a head centre ``(tdx, tdy)`` with the image.

    ``from_bottom``: ``tdy`` counts rows from the bottom row (300W-LP ``Pose_Para``: row = ``H - 1 - tdy``),
    so it is turned into a row with the input height ``h_in`` and back with the output height ``h_out``.
    """
    tdy = np.asarray(tdy, dtype=np.float64)
    fb = np.asarray(from_bottom, dtype=bool)
    v = np.where(fb, np.asarray(h_in, dtype=np.float64) - 1.0 - tdy, tdy)
    u2, v2 = move_point(tdx, v, P)
    return u2, np.where(fb, np.asarray(h_out, dtype=np.float64) - 1.0 - v2, v2)


def move_points(points, P, mirror=False, perm=None) -> np.ndarray:
    """Landmarks (..., L, 2) moved by pixel affines ``P`` (..., 2, 3); re-indexed by ``perm`` where ``mirror``."""
    pts = np.asarray(points, dtype=np.float64)
    mirror = np.asarray(mirror, dtype=bool)
    if mirror.any() and perm is None:
        raise ValueError(f"a mirror needs a left/right permutation for the {pts.shape[-2]} landmarks, got none")
    return _move_points(pts, np.asarray(P, dtype=np.float64), mirror, perm)


def move_boxes(boxes, P, M, out_size, points=None, box_from: str = "auto", clip: bool = False) -> np.ndarray:
    """Boxes (..., 4) moved by pixel affines ``P``; see :func:`augment_boxes` (``out_size`` = output ``(W, H)``)."""
    return _move_boxes(
        np.asarray(boxes, dtype=np.float64),
        np.asarray(P, dtype=np.float64),
        check_plane(M)[0],
        _image_size(out_size),
        points,
        box_from,
        clip,
    )


def _apply_affine(P, pts):
    """``P`` (..., 2, 3) applied to points (..., L, 2)."""
    # one batched matmul beats elementwise formulas on (N, L, 2) by ~10x (no strided temporaries)
    return pts @ np.swapaxes(P[..., :2], -1, -2) + P[..., None, :, 2]


def augment_points(points, M, image_size, perm=None) -> np.ndarray:
    """Move 2-D landmarks with the image and, for mirrors, re-index them.

    Parameters
    ----------
    points : array_like, shape (..., L, 2)
        Pixel coordinates ``(u, v)`` (centres at integers). NaN (missing) stays NaN.
    M : array_like, shape (..., 2, 2)
        Image-plane matrices (x right, y up), broadcast against ``points``.
    image_size : array_like, shape (..., 2)
        ``(W, H)`` in pixels.
    perm : array_like of int, shape (L,), optional
        Left/right permutation (:mod:`~hpe_cli.geometry.landmark_schemes`);
        required when any ``M`` is a mirror. ``new[i] = moved[perm[i]]``.

    Returns
    -------
    ndarray, shape (..., L, 2)
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim < 2 or pts.shape[-1] != 2:
        raise ValueError(f"expected landmarks of shape (..., L, 2), got {pts.shape}")
    M, det = check_plane(M)
    mirror = det < 0
    if mirror.any():
        if perm is None:
            raise ValueError(
                f"a mirror needs a left/right permutation for the {pts.shape[-2]} landmarks "
                "(see hpe_cli.geometry.landmark_schemes), got none"
            )
        perm = flip_permutation(perm, pts.shape[-2])
    return _move_points(pts, plane_to_pixel(M, _image_size(image_size)), mirror, perm)


def _move_points(pts, P, mirror, perm):
    moved = _apply_affine(P, pts)
    if not mirror.any():
        return moved
    if mirror.all():
        return moved[..., perm, :]
    return np.where(mirror[..., None, None], moved[..., perm, :], moved)


def box_of_points(points, min_points: int = 2):
    """Axis-aligned box ``(x, y, w, h)`` of the finite points of each row.

    Parameters
    ----------
    points : array_like, shape (..., L, 2)
    min_points : int
        Rows with fewer finite points get NaN.

    Returns
    -------
    box : ndarray, shape (..., 4)
    ok : ndarray of bool, shape (...)
    """
    pts = np.asarray(points, dtype=np.float64)
    x, y = pts[..., 0], pts[..., 1]
    fin = np.isfinite(x) & np.isfinite(y)
    ok = fin.sum(axis=-1) >= min_points
    # x and y reduced separately: contiguous (N, L) reductions are much faster than over axis -2
    xs, ys = np.where(fin, x, np.inf), np.where(fin, y, np.inf)
    x0, y0 = xs.min(axis=-1), ys.min(axis=-1)
    xs[~fin], ys[~fin] = -np.inf, -np.inf
    box = np.stack([x0, y0, xs.max(axis=-1) - x0, ys.max(axis=-1) - y0], axis=-1)
    return np.where(ok[..., None], box, np.nan), ok


def augment_boxes(boxes, M, image_size, points=None, box_from: str = "auto", clip: bool = False) -> np.ndarray:
    """Move boxes ``(x, y, w, h)`` with the image.

    Parameters
    ----------
    boxes : array_like, shape (..., 4)
        Pixel coordinates (centres at integers): corners ``(x, y)``, ``(x+w, y+h)``.
    M : array_like, shape (..., 2, 2)
        Image-plane matrices (x right, y up).
    image_size : array_like, shape (..., 2)
        ``(W, H)`` in pixels.
    points : array_like, shape (..., L, 2), optional
        The **already moved** landmarks of each row.
    box_from : {"auto", "landmarks", "corners"}
        ``corners``: the box of the 4 moved corners. ``landmarks``: the box of
        the row's finite moved landmarks (at least 2), else the corners.
        ``auto``: corners when ``M`` maps axis-aligned boxes to axis-aligned
        boxes exactly (flips, rotations by multiples of 90, mirrors about lines
        at multiples of 45), else as ``landmarks``: a rotated box's hull would
        grow at every augmentation.
    clip : bool
        Clip the box to the pixel centres ``[0, W-1] x [0, H-1]`` (a range each
        flip maps to itself). Off by default: a box partly outside the image
        still says where the head is.

    Returns
    -------
    ndarray, shape (..., 4)
        NaN where the input box is not finite and no landmark box was used.
    """
    if box_from not in BOX_FROM:
        raise ValueError(f"expected box_from in {', '.join(BOX_FROM)}, got {box_from!r}")
    b = np.asarray(boxes, dtype=np.float64)
    if b.shape[-1:] != (4,):
        raise ValueError(f"expected boxes of shape (..., 4), got {b.shape}")
    M, _ = check_plane(M)
    wh = _image_size(image_size)
    return _move_boxes(b, plane_to_pixel(M, wh), M, wh, points, box_from, clip)


def _move_boxes(b, P, M, wh, points, box_from, clip):
    x, y, w, h = (b[..., i] for i in range(4))
    corners = np.stack(
        [np.stack([x, y], -1), np.stack([x + w, y], -1), np.stack([x, y + h], -1), np.stack([x + w, y + h], -1)],
        axis=-2,
    )
    moved = _apply_affine(P, corners)
    lo, hi = moved.min(axis=-2), moved.max(axis=-2)
    out = np.concatenate([lo, hi - lo], axis=-1)
    if box_from != "corners" and points is not None:
        lm_box, ok = box_of_points(points)
        use = ok
        if box_from == "auto":
            axis_aligned = (np.abs(M) < 1e-12).any(axis=(-1, -2))
            use = ok & ~axis_aligned
        out = np.where(use[..., None], lm_box, out)
    if clip:
        wh = np.broadcast_to(wh, out.shape[:-1] + (2,))
        lo = np.clip(out[..., :2], 0.0, wh - 1.0)
        hi = np.clip(out[..., :2] + out[..., 2:], 0.0, wh - 1.0)
        out = np.concatenate([lo, hi - lo], axis=-1)
    return out


@dataclass
class Augmented:
    """Labels after an augmentation, in the input's rotation system.

    Attributes
    ----------
    matrix : ndarray, shape (N, 3, 3) (or (3, 3))
        The system's stored matrix.
    angles, angles_2 : ndarray, shape (N, 3) (or (3,))
        ``(pitch, yaw, roll)`` in degrees, primary and secondary solution, in ``(-180, 180]``.
    canonical : ndarray, shape (N, 3, 3) (or (3, 3))
        The canonical 300W-LP matrix ``A'``.
    gimbal_lock : ndarray of bool, shape (N,) (or ())
    landmarks : ndarray, shape (N, L, 2) (or (L, 2)), or None
    bbox : ndarray, shape (N, 4) (or (4,)), or None
    """

    matrix: np.ndarray
    angles: np.ndarray
    angles_2: np.ndarray
    canonical: np.ndarray
    gimbal_lock: np.ndarray
    landmarks: np.ndarray | None
    bbox: np.ndarray | None


def _resolve_perm(scheme, n_landmarks):
    if scheme is None:
        return None
    if isinstance(scheme, str) and scheme == "auto":
        name = scheme_for_count(n_landmarks)
        return None if name is None else flip_permutation(name)
    return flip_permutation(scheme, n_landmarks)


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
) -> Augmented:
    """Augment N samples at once: labels, landmarks and boxes.

    Parameters
    ----------
    pose : array_like, shape (N, 3) or (N, 3, 3)
        ``(pitch, yaw, roll)`` in degrees, or the stored matrices, of ``system``.
    landmarks : array_like, shape (N, L, 2), optional
        Pixel coordinates (centres at integers, rows going down); NaN = missing.
    bbox : array_like, shape (N, 4), optional
        ``(x, y, w, h)`` in the same pixel coordinates.
    op : {"hflip", "vflip", "hvflip", "rotate", "mirror"} or array_like, shape (N, 2, 2) or (2, 2)
        An operation name (see :func:`plane_matrix`) or image-plane matrices
        (x right, y up), e.g. products of :func:`plane_matrix` results.
    angle : float or array_like, shape (N,), optional
        Degrees for ``rotate`` (counter-clockwise on screen) and ``mirror``
        (line angle); an array gives each row its own angle.
    image_size : array_like, shape (2,) or (N, 2)
        ``(W, H)`` in pixels.
    system : str, path or RotationSystem
        Rotation system of ``pose`` and of the result (default ``300w_lp``).
    scheme : "auto", {"ibug68", "face70", "aflw21"}, array_like of int, or None
        Left/right landmark permutation used after a mirror. ``auto`` picks the
        built-in scheme with L points (68, 70, 21).
    box_from, clip
        See :func:`augment_boxes`.

    Returns
    -------
    Augmented

    Raises
    ------
    ValueError
        Bad shapes, a non-orthogonal ``op`` matrix, or a mirror with landmarks
        and no permutation.

    Examples
    --------
    >>> out = augment_batch([[20.0, -50.0, 15.0]], op="rotate", angle=30, image_size=(450, 450))
    >>> out.angles.round(3)
    array([[ 43.511, -33.607, -19.343]])
    """
    sysm = get_system(system)
    pose = np.asarray(pose, dtype=np.float64)
    if pose.ndim == 2 and pose.shape[-1] == 3:
        A = sysm.to_canonical(sysm.from_angles(pose))
    elif pose.ndim == 3 and pose.shape[-2:] == (3, 3):
        A = sysm.to_canonical(pose)
    else:
        raise ValueError(f"expected pose of shape (N, 3) angles or (N, 3, 3) matrices, got {pose.shape}")
    n = A.shape[0]
    M = plane_matrix(op, angle) if isinstance(op, str) else np.asarray(op, dtype=np.float64)
    M, det = check_plane(M)
    if M.ndim > 2 and M.shape[0] not in (1, n):
        raise ValueError(f"expected one op matrix or {n}, got {M.shape[0]}")
    conv = canonical_to_labels(_canonical(A, M, det), sysm)
    wh = _image_size(image_size)
    P = plane_to_pixel(M, wh)
    lm_out = None
    if landmarks is not None:
        lm = np.asarray(landmarks, dtype=np.float64)
        if lm.ndim != 3 or lm.shape[0] != n or lm.shape[-1] != 2:
            raise ValueError(f"expected landmarks of shape ({n}, L, 2), got {lm.shape}")
        mirror = det < 0
        perm = _resolve_perm(scheme, lm.shape[1])
        if perm is None and mirror.any():
            raise ValueError(
                f"a mirror needs a left/right permutation for the {lm.shape[1]} landmarks: "
                "pass scheme= a name or an index array, got none"
            )
        lm_out = _move_points(lm, P, mirror, perm)
    box_out = None
    if bbox is not None:
        b = np.asarray(bbox, dtype=np.float64)
        if b.shape != (n, 4):
            raise ValueError(f"expected bbox of shape ({n}, 4), got {b.shape}")
        if box_from not in BOX_FROM:
            raise ValueError(f"expected box_from in {', '.join(BOX_FROM)}, got {box_from!r}")
        box_out = _move_boxes(b, P, M, wh, lm_out, box_from, clip)
    return Augmented(conv.matrix, conv.primary, conv.secondary, conv.canonical, conv.gimbal_lock, lm_out, box_out)


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
) -> Augmented:
    """Augment one sample (for a training pipeline's per-sample transform).

    Parameters
    ----------
    pose : array_like, shape (3,) or (3, 3)
        ``(pitch, yaw, roll)`` in degrees, or the stored matrix, of ``system``.
    landmarks : array_like, shape (L, 2), optional
    bbox : array_like, shape (4,), optional
    op, angle, image_size, system, scheme, box_from, clip
        As in :func:`augment_batch` (``angle`` a scalar, ``op`` a name or one (2, 2) matrix).

    Returns
    -------
    Augmented
        With the leading N dimension removed.

    Examples
    --------
    >>> out = augment_sample([10.0, 30.0, 5.0], op="hflip", image_size=(450, 450))
    >>> out.angles.round(6)
    array([ 10., -30.,  -5.])
    """
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape not in ((3,), (3, 3)):
        raise ValueError(f"expected pose of shape (3,) angles or (3, 3) matrix, got {pose.shape}")
    if not isinstance(op, str) and np.asarray(op).shape != (2, 2):
        raise ValueError(f"expected one (2, 2) op matrix, got {np.asarray(op).shape}")
    if angle is not None and np.ndim(angle) != 0:
        raise ValueError(f"expected a scalar angle, got shape {np.shape(angle)}")
    lm = None if landmarks is None else np.asarray(landmarks, dtype=np.float64)[None]
    b = None if bbox is None else np.asarray(bbox, dtype=np.float64)[None]
    out = augment_batch(
        pose[None],
        lm,
        b,
        op=op,
        angle=angle,
        image_size=image_size,
        system=system,
        scheme=scheme,
        box_from=box_from,
        clip=clip,
    )
    return Augmented(
        out.matrix[0],
        out.angles[0],
        out.angles_2[0],
        out.canonical[0],
        out.gimbal_lock[0],
        None if out.landmarks is None else out.landmarks[0],
        None if out.bbox is None else out.bbox[0],
    )
