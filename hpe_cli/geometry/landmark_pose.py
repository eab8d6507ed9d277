"""Head rotation from 2-D landmarks alone: a batched weak-perspective fit of a 3-D face model.

Model
-----
The 3-D model is :func:`hpe_cli.geometry.template.reference_template`, DirectMHP's
68-point mean face mapped to the canonical 300W-LP frame (x subject's left, y up, z
out of the face; how its frame was established is in that module's notes). Each
landmark scheme is a weight matrix ``W`` (L x 68): its model point ``l`` is
``W[l] @ template`` (:data:`SCHEME_POINTS` says which iBUG-68 points):

``ibug68``
    The 51 inner points 17-67 (brows, nose, eyes, mouth). The jaw contour 0-16 is
    not used: in a turned face, 2-D annotations put it on the silhouette, not on
    fixed points of the head (on the 300W-LP sample at yaw -44, all 68 points give
    14.9 deg to the label, the inner 51 give 3.7 deg).
``face70``
    CMU Panoptic's face70: the inner iBUG points as above, then the pupils 68
    (subject's right eye) and 69 (left eye), modelled as the mean of that eye's six
    contour points.
``aflw21``
    The 21 AFLW points of AFLW2000-3D ``pt2d``: brows 0-5 -> 17, 19, 21, 22, 24, 26;
    eyes 6-11 -> 36, mean(37, 38, 40, 41), 39, 42, mean(43, 44, 46, 47), 45; nose
    13-15 -> 31, 30, 35; mouth 17-19 -> 48, mean(62, 66), 54; chin 20 -> 8. The ears
    (12, 16) have no iBUG point and are not used. The pairs were read off the 16
    AFLW2000-3D samples by the nearest ``pt3d_68`` point to each ``pt2d`` point
    (median distance 0.03-0.07 inter-ocular distances).

Fit
---
Weak perspective (scaled orthographic): a model point ``X`` (canonical frame) goes
to the image pixel ``(u, v) = s * (A X)_x + t_u, -s * (A X)_y + t_v`` (image y points
down), with ``A`` the 300W-LP active matrix of the head. Per row:

1. the affine camera ``[u v] = M X + t`` (2 x 3 ``M``) by weighted linear least
   squares over the visible points (one 4 x 4 normal system per row, all rows in one
   ``numpy.linalg.solve``);
2. the nearest scaled rotation: rows ``r1 = M[0]``, ``r2 = -M[1]`` (the y flip), SVD
   ``[r1; r2] = U S V^T``; ``Q = U V^T`` has orthonormal rows, ``s = mean(S)`` and
   ``A = [q1; q2; q1 x q2]`` is proper (det +1) by construction; the depth sign is
   fixed by the model being 3-D (a flat model would leave the Necker ambiguity);
3. the translation again for that ``s A`` and the reprojection residual.

Noise-free projections are recovered exactly (the affine camera of a weak
perspective view *is* a scaled rotation); with noise, step 2 is the usual
projection of the affine solution onto scaled rotations (Tomasi & Kanade 1992,
metric constraints; POSIT's first iteration, DeMenthon & Davis 1995).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..rotation.distances import geodesic_deg
from .line_of_sight import ray_rotation
from .template import reference_template

#: fewest visible model points a fit accepts (the affine camera has 8 unknowns)
MIN_POINTS = 6

#: ratio of the second to the first singular value of the affine camera below which
#: the fit is degenerate (all visible points on a line, or a camera that squashes the face)
MIN_SINGULAR_RATIO = 0.2

# scheme -> per landmark: the iBUG-68 points averaged (empty: no model point)
_EYE_R, _EYE_L = (37, 38, 40, 41), (43, 44, 46, 47)
SCHEME_POINTS = {
    "ibug68": ((),) * 17 + tuple((i,) for i in range(17, 68)),
    "face70": ((),) * 17 + tuple((i,) for i in range(17, 68)) + ((36, 37, 38, 39, 40, 41), (42, 43, 44, 45, 46, 47)),
    "aflw21": (
        (17,), (19,), (21,), (22,), (24,), (26,),
        (36,), _EYE_R, (39,), (42,), _EYE_L, (45,),
        (), (31,), (30,), (35,), (),
        (48,), (62, 66), (54,), (8,),
    ),
}  # fmt: skip

#: scheme -> landmark count
SCHEME_SIZES = {k: len(v) for k, v in SCHEME_POINTS.items()}


#: inter-ocular distance of the template (outer eye corners 36, 45), the residual's unit
def _iod(T) -> float:
    return float(np.linalg.norm(T[45] - T[36]))


@lru_cache(maxsize=None)
def scheme_model(scheme: str) -> tuple[np.ndarray, np.ndarray]:
    """The 3-D model points of a landmark scheme.

    Parameters
    ----------
    scheme : {"ibug68", "face70", "aflw21"}

    Returns
    -------
    points : ndarray, shape (L, 3)
        Model points in the canonical frame, template units (NaN where unused).
    used : ndarray of bool, shape (L,)
        Landmarks that have a model point.
    """

    if scheme not in SCHEME_POINTS:
        raise ValueError(f"expected a landmark scheme in {', '.join(SCHEME_POINTS)}, got {scheme!r}")
    T = reference_template()
    rows = SCHEME_POINTS[scheme]
    pts = np.full((len(rows), 3), np.nan)
    for i, idx in enumerate(rows):
        if idx:
            pts[i] = T[list(idx)].mean(0)
    used = np.isfinite(pts).all(1)
    pts.setflags(write=False)
    used.setflags(write=False)
    return pts, used


def template_iod() -> float:
    """Inter-ocular distance (outer corners) of the template, in template units (about 0.84)."""

    return _iod(reference_template())


#: why a row was not fitted, by ``code`` (0: fitted)
FIT_REASONS = ("", f"fewer than {MIN_POINTS} visible landmarks", "degenerate landmarks (collinear or squashed)")


def fit_landmark_pose(uv, scheme: str = "ibug68", visible=None, *, reasons: bool = True) -> dict:
    """Weak-perspective rotation of many faces from their 2-D landmarks.

    Parameters
    ----------
    uv : array_like, shape (N, L, 2)
        Landmark pixels (x right, y down). NaN, or ``(-1, -1)`` (AFLW's
        convention), marks an invisible point.
    scheme : {"ibug68", "face70", "aflw21"}
        Landmark order; ``L`` must be its size (68, 70, 21).
    visible : array_like of bool, shape (N, L), optional
        Further restricts the points used.
    reasons : bool
        ``True`` (default): ``reason`` texts; ``False``: ``code`` (see Returns).

    Returns
    -------
    dict
        ``A`` (N, 3, 3): the fitted 300W-LP active matrix (canonical frame, det +1);
        ``scale`` (N,): pixels per template unit; ``t`` (N, 2): pixel position of
        the model origin; ``residual`` (N,): RMS reprojection distance over the
        used points divided by the projected inter-ocular distance (``scale *
        template_iod()``), dimensionless, about 0.03-0.1 on real faces;
        ``n_points`` (N,) int; ``reason`` (N,) object: ``""`` when fitted, else
        why not (``"fewer than 6 visible landmarks"``, ``"degenerate landmarks
        (collinear or squashed)"``). Rows not fitted have NaN in ``A``,
        ``scale``, ``t`` and ``residual``. With ``reasons=False``, ``code``
        (N,) uint8 instead of ``reason``: an index into :data:`FIT_REASONS`
        (no array of Python strings: the consistency audit's hot path).
    """
    model, used = scheme_model(scheme)
    uv = np.asarray(uv, dtype=np.float64)
    L = model.shape[0]
    if uv.ndim != 3 or uv.shape[1:] != (L, 2):
        raise ValueError(f"expected landmarks of shape (N, {L}, 2) for scheme {scheme}, got {uv.shape}")
    if visible is not None:
        visible = np.asarray(visible, dtype=bool)
    N = uv.shape[0]
    if N <= BLOCK:
        out = _fit_block(uv, model, used, visible)
    else:
        # blocks that stay in cache: the work is a dozen passes over (rows x points) arrays
        parts = [
            _fit_block(uv[s : s + BLOCK], model, used, None if visible is None else visible[s : s + BLOCK])
            for s in range(0, N, BLOCK)
        ]
        out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    if reasons:
        out["reason"] = np.array(FIT_REASONS, dtype=object)[out.pop("code")]
    return out


#: rows per block of :func:`fit_landmark_pose`
BLOCK = 16384


@lru_cache(maxsize=None)
def _full_inverse(scheme_key: bytes, L: int) -> np.ndarray:
    """Inverse normal matrix of a row whose model points are all visible (the same for every such row)."""
    model = np.frombuffer(scheme_key).reshape(L, 3)
    used = np.isfinite(model).all(1)
    Xh = np.concatenate([model[used], np.ones((used.sum(), 1))], axis=1)
    return np.linalg.inv(Xh.T @ Xh)


def _fit_block(uv, model, used, visible) -> dict:
    L = model.shape[0]
    u, v = uv[..., 0], uv[..., 1]
    vis = np.isfinite(u) & np.isfinite(v) & ~((u == -1.0) & (v == -1.0)) & used[None, :]
    if visible is not None:
        vis &= visible
    N = uv.shape[0]
    w = vis.astype(np.float64)
    n = w.sum(1)
    u0 = np.where(vis, u, 0.0)
    v0 = np.where(vis, v, 0.0)  # zeroed where unused, so NaN never enters a sum
    Xh = np.concatenate([np.nan_to_num(model), np.ones((L, 1))], axis=1)  # (L, 4)
    outer = (Xh[:, :, None] * Xh[:, None, :]).reshape(L, 16)
    G = (w @ outer).reshape(N, 4, 4)  # sum of w X X^T: one BLAS product for all rows
    rhs = np.stack([u0 @ Xh, v0 @ Xh], axis=-1)  # (N, 4, 2); invisible points are zero
    few = n < MIN_POINTS
    G[few] = np.eye(4)
    full = n == used.sum()  # every model point visible: one shared inverse
    sol = np.empty((N, 4, 2))
    if full.any():
        sol[full] = np.einsum("ij,njk->nik", _full_inverse(model.tobytes(), L), rhs[full])
    part = ~full
    if part.any():
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            try:
                sol[part] = np.linalg.solve(G[part], rhs[part])  # (n, 4, 2)
            except np.linalg.LinAlgError:  # a singular row: each with lstsq
                sol[part] = np.stack([np.linalg.lstsq(g, r, rcond=None)[0] for g, r in zip(G[part], rhs[part])])
    # rows s*A[0] and s*A[1] of the affine camera (v grows downwards: negate its row)
    b1 = np.where(np.isfinite(sol[:, :3, 0]), sol[:, :3, 0], 0.0)
    b2 = np.where(np.isfinite(sol[:, :3, 1]), -sol[:, :3, 1], 0.0)
    # nearest scaled orthonormal rows: Q = (B B^T)^(-1/2) B, in closed form for the 2 x 2 Gram matrix
    c11 = (b1 * b1).sum(1)
    c22 = (b2 * b2).sum(1)
    c12 = (b1 * b2).sum(1)
    det = np.maximum(c11 * c22 - c12 * c12, 0.0)
    rdet = np.sqrt(det)  # S1 * S2
    with np.errstate(invalid="ignore", divide="ignore"):
        ssum = np.sqrt(c11 + c22 + 2.0 * rdet)  # S1 + S2
        sdiff = np.sqrt(np.maximum(c11 + c22 - 2.0 * rdet, 0.0))  # S1 - S2
        ratio = (ssum - sdiff) / (ssum + sdiff)  # S2 / S1
        # sqrt(C) = (C + rdet I) / ssum; its inverse is its adjugate over det(sqrt C) = rdet
        k = 1.0 / (ssum * rdet)
        i11, i22, i12 = (c22 + rdet) * k, (c11 + rdet) * k, -c12 * k
        q1 = i11[:, None] * b1 + i12[:, None] * b2
        q2 = i12[:, None] * b1 + i22[:, None] * b2
    A = np.stack([q1, q2, np.cross(q1, q2)], axis=1)
    scale = 0.5 * ssum
    degenerate = ~few & ~(ratio >= MIN_SINGULAR_RATIO)
    # translation and residual for the scaled rotation: one BLAS product per image axis
    Xm = np.nan_to_num(model)
    pu = (scale[:, None] * A[:, 0]) @ Xm.T  # (N, L)
    pv = (-scale[:, None] * A[:, 1]) @ Xm.T
    n_safe = np.maximum(n, 1.0)
    du = u0 - pu
    dv = v0 - pv
    du *= w
    dv *= w
    tu = du.sum(1) / n_safe
    tv = dv.sum(1) / n_safe
    # sum of w |d - t|^2 = sum w |d|^2 - n |t|^2 (w is 0/1)
    ss = np.einsum("nl,nl->n", du, du) + np.einsum("nl,nl->n", dv, dv) - n * (tu * tu + tv * tv)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.maximum(ss, 0.0) / n_safe)
        residual = rms / (scale * template_iod())
    code = np.zeros(N, dtype=np.uint8)
    code[degenerate] = 2
    code[few] = 1
    bad = code != 0
    if bad.any():
        A[bad] = np.nan
        scale = np.where(bad, np.nan, scale)
        tu = np.where(bad, np.nan, tu)
        tv = np.where(bad, np.nan, tv)
        residual = np.where(bad, np.nan, residual)
    return {
        "A": A,
        "scale": scale,
        "t": np.stack([tu, tv], axis=1),
        "residual": residual,
        "n_points": n.astype(np.int64),
        "code": code,
    }


def project_model(A, scale, t, scheme: str = "ibug68") -> np.ndarray:
    """The weak-perspective projection ``(N, L, 2)`` of a scheme's model points (NaN where unused).

    The inverse of :func:`fit_landmark_pose` for noise-free data: ``u = s (A X)_x + t_u``,
    ``v = -s (A X)_y + t_v``.
    """
    model, _ = scheme_model(scheme)
    A = np.asarray(A, dtype=np.float64)
    Y = np.einsum("nij,lj->nli", A, model)
    s = np.asarray(scale, dtype=np.float64)[:, None]
    t = np.asarray(t, dtype=np.float64)
    return np.stack([s * Y[..., 0] + t[:, None, 0], -s * Y[..., 1] + t[:, None, 1]], axis=-1)


def landmark_disagreement(A_label, uv, scheme: str = "ibug68") -> dict:
    """Fit the landmarks and measure the angle between the fit and the label.

    Parameters
    ----------
    A_label : array_like, shape (N, 3, 3)
        The labels as 300W-LP active matrices (canonical frame).
    uv, scheme
        As :func:`fit_landmark_pose`.

    Returns
    -------
    dict
        :func:`fit_landmark_pose`'s keys plus ``angle`` (N,), the geodesic angle
        between the fit and the label in degrees, [0, 180] (NaN when not fitted).
    """
    fit = fit_landmark_pose(uv, scheme)
    fit["angle"] = geodesic_deg(np.asarray(A_label, dtype=np.float64), fit["A"])
    return fit


#: fixed-point iterations that invert OpenCV's lens distortion (as ``cv2.undistortPoints``)
UNDISTORT_ITERATIONS = 8


def undistort_normalised(uv, K, dist) -> np.ndarray:
    """Pixels ``(N, L, 2)`` to undistorted normalised coordinates, per row's camera.

    ``K`` (N, 3, 3) and ``dist`` (N, 5) (OpenCV's ``k1, k2, p1, p2, k3``): the
    fixed-point inversion of :func:`hpe_cli.geometry.projection.distort` that
    ``cv2.undistortPoints`` uses (``x = (x_d - tangential(x)) / radial(x)``).
    """
    uv = np.asarray(uv, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)[:, None]
    dist = np.asarray(dist, dtype=np.float64)[:, None]
    yd = (uv[..., 1] - K[..., 1, 2]) / K[..., 1, 1]
    xd = (uv[..., 0] - K[..., 0, 2] - K[..., 0, 1] * yd) / K[..., 0, 0]
    x, y = xd.copy(), yd.copy()
    k1, k2, p1, p2, k3 = (dist[..., i] for i in range(5))
    for _ in range(UNDISTORT_ITERATIONS):
        r2 = x * x + y * y
        f = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        x = (xd - (2 * p1 * x * y + p2 * (r2 + 2 * x * x))) / f
        y = (yd - (p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)) / f
    return np.stack([x, y], -1)


def fit_landmark_pose_perspective(uv, scheme: str, K, dist=None, *, reasons: bool = True) -> dict:
    """:func:`fit_landmark_pose` for a calibrated camera, corrected for where the head is in the image.

    A weak-perspective fit sees the head along the ray through it, not along the
    optical axis: a head near the image border looks turned by the angle
    between them (up to 30 deg on CMU Panoptic's HD cameras). The landmarks are
    undistorted and normalised with ``K`` and ``dist``, turned by ``Q.T`` (``Q``
    the smallest rotation taking the optical axis to the ray through their
    centroid, :func:`hpe_cli.geometry.line_of_sight.ray_rotation`) so the head is
    on the axis of a virtual camera, fitted there, and the fit is turned back:
    ``A = (E Q E) A_virtual``, ``E = diag(1, -1, -1)`` (the inverse of
    :func:`hpe_cli.geometry.line_of_sight.camera_to_crop_labels`).

    Parameters
    ----------
    uv : array_like, shape (N, L, 2)
        Pixels, as :func:`fit_landmark_pose`.
    scheme : str
    K : array_like, shape (N, 3, 3)
    dist : array_like, shape (N, 5), optional
        Zero distortion by default.
    reasons : bool
        As :func:`fit_landmark_pose`.

    Returns
    -------
    dict
        As :func:`fit_landmark_pose`, with ``A`` in the camera frame, ``scale``
        in normalised units (1 / focal length) and ``ray_angle`` (N,) degrees.
    """

    uv = np.asarray(uv, dtype=np.float64)
    N = uv.shape[0]
    dist = np.zeros((N, 5)) if dist is None else np.asarray(dist, dtype=np.float64)
    invisible = ~np.isfinite(uv).all(-1) | ((uv[..., 0] == -1.0) & (uv[..., 1] == -1.0))
    xy = undistort_normalised(np.where(invisible[..., None], 0.0, uv), K, dist)
    xy[invisible] = np.nan
    rays = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1)
    with np.errstate(invalid="ignore"):
        c = np.nanmean(rays, axis=1)
    Q, angle = ray_rotation(np.where(np.isfinite(c), c, [0.0, 0.0, 1.0]))
    v = np.einsum("nji,nlj->nli", Q, rays)  # Q.T @ ray
    with np.errstate(invalid="ignore", divide="ignore"):
        virt = v[..., :2] / v[..., 2:3]
    fit = fit_landmark_pose(virt, scheme, reasons=reasons)
    E = np.diag([1.0, -1.0, -1.0])
    fit["A"] = E @ Q @ E @ fit["A"]
    fit["ray_angle"] = angle
    return fit
