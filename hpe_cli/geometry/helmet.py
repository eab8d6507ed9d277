"""The head box ("helmet") of WHENet and DirectMHP, with the correct lens model.

A sphere of points around the fitted reference head (SPEC §6) is mapped into
the world with the face's similarity ``scale * R @ p + t``, projected into the
camera with :func:`~hpe_cli.geometry.projection.project_points`'s model, and
its min/max is the box, clamped to the image. Each preset then applies its
own sanity rule. Every row gets a reason when it is rejected, in this order:

- ``"no fit"``: the similarity is NaN (too few pairs upstream);
- ``"behind camera"``: a helmet point has depth ``z <= 0`` (the projection of
  a sphere that crosses the camera plane is unbounded);
- ``"outside image"``: the helmet centre projects outside the image, a helmet
  point lies beyond the field where the distortion polynomial is monotonic
  (there it folds back and lies about where a point lands), or the clamped
  box is empty;
- ``"box rejected"``: the preset's aspect-ratio or size rule fails.
"""

from __future__ import annotations

import numpy as np

from .projection import distort, max_valid_r2
from .reference import helmet_preset

#: face-camera rows projected per block: keeps temporaries inside the CPU cache
BLOCK_ROWS = 128
#: precision of the 613 helmet points per view: float32 is 1.5x faster than float64
#: and moves a box corner by less than 1e-3 pixel (the helmet centre, the checks
#: and everything else stay float64)
DTYPE = np.float32


#: a fixed random projection that tells distortion vectors apart cheaply
_HASH = np.random.default_rng(7).normal(size=5)


def helmet_points(radius, offset=(0, 5, -5)) -> np.ndarray:
    """The helmet sphere in reference-head units, shape (648, 3).

    ``theta`` runs over 0, 10, ..., 350 degrees (outer loop) and ``phi`` over
    0, 10, ..., 170 (inner loop); a point is
    ``radius * (cos theta sin phi, sin theta sin phi, cos phi) + offset``,
    in WHENet's order (its ``get_sphere``).
    """
    theta = np.deg2rad(np.arange(0, 360, 10, dtype=np.float64))[:, None]
    phi = np.deg2rad(np.arange(0, 180, 10, dtype=np.float64))[None, :]
    pts = np.stack(
        np.broadcast_arrays(np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi) + 0 * theta), axis=-1
    ).reshape(-1, 3)
    return float(radius) * pts + np.asarray(offset, dtype=np.float64)


def _per_row(a, n: int, tail: tuple) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape == tail:
        return np.broadcast_to(a, (n,) + tail)
    if tail == (3,) and a.shape == (3, 1):
        return np.broadcast_to(a[:, 0], (n, 3))
    if tail == (3,) and a.shape == (n, 3, 1):
        return a[..., 0]
    if a.shape != (n,) + tail:
        raise ValueError(f"expected shape {tail} or {(n,) + tail}, got {a.shape}")
    return a


def helmet_boxes(
    scale, R, t, K, dist, cam_R, cam_t, width, height, preset="whenet", *, return_centre: bool = False
) -> dict:
    """Head boxes of fitted faces seen by cameras (SPEC §6).

    Parameters
    ----------
    scale : array_like, shape (N,)
        Similarity scale (world units per reference-head unit; ~1 on Panoptic, cm).
    R : array_like, shape (N, 3, 3)
        Head rotation (reference head -> world).
    t : array_like, shape (N, 3)
        Head translation, world units.
    K, dist, cam_R, cam_t : array_like
        One camera (``(3, 3)``, ``(5,)``, ``(3, 3)``, ``(3,)`` or ``(3, 1)``)
        or one per row (with a leading ``N``). ``cam_R @ X + cam_t`` is the
        OpenCV camera frame.
    width, height : int or array_like (N,)
        Image size in pixels.
    preset : {"whenet", "directmhp"} or HelmetPreset
        Sphere radius and box rule (:func:`~hpe_cli.geometry.reference.helmet_preset`).
    return_centre : bool
        Also return ``centre`` (N, 2): the helmet centre in pixels.

    Returns
    -------
    dict
        ``bbox`` (N, 4) float ``x, y, w, h`` in pixels, the min/max of the
        projected helmet clamped to ``[0, width] x [0, height]`` (NaN where the
        helmet cannot be projected; WHENet and DirectMHP truncate the corners
        to integers, hpe keeps them exact and applies the rules to them); ``ok`` (N,) bool; ``reason`` (N,) object:
        ``''`` or one of ``"no fit"``, ``"behind camera"``, ``"outside image"``,
        ``"box rejected"``; ``detail`` (N,) object: a short explanation.
    """
    p = helmet_preset(preset)
    scale = np.asarray(scale, dtype=np.float64).reshape(-1)
    n = scale.shape[0]
    R, t = _per_row(R, n, (3, 3)), _per_row(t, n, (3,))
    K, dist = _per_row(K, n, (3, 3)), _per_row(_five(dist), n, (5,))
    cam_R, cam_t = _per_row(cam_R, n, (3, 3)), _per_row(cam_t, n, (3,))
    W = np.broadcast_to(np.asarray(width, dtype=np.float64), (n,))
    H = np.broadcast_to(np.asarray(height, dtype=np.float64), (n,))

    # camera frame of a helmet point: M @ u + c, M = scale * radius * cam_R @ R,
    # c = cam_R @ (scale * R @ offset + t) + cam_t
    centre_ref = np.asarray(p.offset, dtype=np.float64)
    G = scale[:, None, None] * (cam_R @ R)
    M = p.radius * G
    c = np.einsum("nij,nj->ni", G, np.broadcast_to(centre_ref, (n, 3))) + np.einsum("nij,nj->ni", cam_R, t) + cam_t
    lo, hi, behind, beyond, fitted = _helmet_extremes(M, c, scale, p.radius, K, dist, cam_R, R)
    cu, cv = _centre_pixels(c, dist, K)
    # the helmet centre, to tell "mostly outside" from "truncated by the border"
    centre_in = (cu >= 0) & (cu < W) & (cv >= 0) & (cv < H)
    bbox, reason, detail = _boxes(lo, hi, W, H, p, (behind, beyond, fitted, centre_in))
    invalid = behind | ~fitted
    bbox[invalid] = np.nan
    out = {"bbox": bbox, "ok": reason == "", "reason": reason, "detail": detail}
    if return_centre:
        out["centre"] = np.where(invalid[:, None], np.nan, np.stack([cu, cv], axis=1))
    return out


def _five(dist) -> np.ndarray:
    """Distortion coefficients padded with zeros to OpenCV's five ``k1, k2, p1, p2, k3``."""
    dist = np.asarray(dist, dtype=np.float64)
    if dist.shape[-1] == 5:
        return dist
    return np.concatenate([dist, np.zeros(dist.shape[:-1] + (5 - dist.shape[-1],))], -1)


def _sphere_grid() -> tuple:
    """``(cos theta, sin theta, sin phi, cos phi)`` of the helmet's theta x phi grid (10-degree steps).

    For a rotation-scale M, M @ u(theta, phi) = sin(phi) (cos(theta) M[:, 0] + sin(theta) M[:, 1]) +
    cos(phi) M[:, 2], so each camera coordinate costs one multiply-add per point. The 36 points at phi = 0
    coincide (the pole) and are projected once.
    """
    theta = np.deg2rad(np.arange(0, 360, 10, dtype=np.float64))
    phi = np.deg2rad(np.arange(10, 180, 10, dtype=np.float64))
    return np.cos(theta), np.sin(theta), np.sin(phi), np.cos(phi)


def _helmet_extremes(M, c, scale, radius, K, dist, cam_R, R) -> tuple:
    """``(lo, hi, behind, beyond, fitted)``: per row the min and max pixel (N, 2) of the projected helmet
    points ``M @ u + c`` (camera frame), whether it reaches behind the camera or beyond the lens model's field,
    and whether the row has a fit."""
    n = len(c)
    # the lens model's valid field depends on the camera only: evaluate it per distinct camera
    _, first, inv = np.unique(dist @ _HASH, return_index=True, return_inverse=True)
    r2_max = max_valid_r2(dist[first])[inv.reshape(-1)]
    lo = np.full((n, 2), np.nan)
    hi = np.full((n, 2), np.nan)
    behind = np.zeros(n, dtype=bool)
    beyond = np.zeros(n, dtype=bool)
    fitted = np.isfinite(M).all((1, 2)) & np.isfinite(c).all(1)
    Mf = np.where(fitted[:, None, None], M, 0.0)
    cf = np.where(fitted[:, None], c, 0.0)
    # Every helmet point lies on the sphere |P - c| = rho, so min z >= c_z - rho and the
    # angle off the optical axis is at most angle(c) + asin(rho / |c|): rows where these
    # bounds already settle "behind" and "beyond" skip the per-point checks.
    rho = np.abs(scale) * radius
    dist_c = np.linalg.norm(c, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.arccos(np.clip(c[:, 2] / dist_c, -1.0, 1.0)) + np.arcsin(np.clip(rho / dist_c, 0.0, 1.0))
        safe_front = c[:, 2] - rho > 0
        safe_field = safe_front & (off < np.pi / 2) & (np.tan(np.minimum(off, 1.5)) ** 2 < r2_max)
    Mf32, cf32, dist32 = Mf.astype(DTYPE), cf.astype(DTYPE), dist.astype(DTYPE)
    # Rows whose helmet is small in the image (angular radius < FAST_MAX_ANGLE), surely in front and inside
    # the lens model's field, with fx, fy > 0 and no skew, take the fast path: only the grid points near the
    # four tangent points of the sphere are projected (same float32 arithmetic, so the same box).
    with np.errstate(divide="ignore", invalid="ignore"):
        small = rho / dist_c < np.sin(np.deg2rad(FAST_MAX_ANGLE))
    fast = fitted & safe_field & small & (scale > 0) & (K[:, 0, 0] > 0) & (K[:, 1, 1] > 0) & (K[:, 0, 1] == 0)
    if FAST and fast.any():
        fi = np.flatnonzero(fast)
        for s in range(0, len(fi), FAST_BLOCK_ROWS):
            idx = fi[s : s + FAST_BLOCK_ROWS]
            lo[idx], hi[idx] = _fast_extremes(
                Mf32[idx], cf32[idx], dist32[idx], K[idx], cam_R[idx] @ R[idx], c[idx], rho[idx], dist[idx]
            )
    slow = np.flatnonzero(~fast) if FAST else np.arange(n)
    grid = tuple(a.astype(DTYPE) for a in _sphere_grid())
    for s in range(0, len(slow), BLOCK_ROWS):
        sl = slow[s : s + BLOCK_ROWS]
        lo[sl], hi[sl], b_behind, b_beyond = _block_extremes(
            Mf32[sl], cf32[sl], dist32[sl], K[sl], grid, safe_front[sl].all(), safe_field[sl].all(), r2_max[sl]
        )
        if b_behind is not None:
            behind[sl] = b_behind
        if b_beyond is not None:
            beyond[sl] = b_beyond
    return lo, hi, behind, beyond, fitted


def _block_extremes(m, cc, d, k, grid, all_front, all_in_field, r2_max) -> tuple:
    """One block of rows, every grid point projected (float32): ``(lo, hi, behind or None, beyond or None)``
    (``behind``/``beyond`` are None when the sphere bounds already settled them for the whole block)."""
    ct, st, sp, cp = grid
    b = m.shape[0]
    planes = []
    for i in range(3):
        ring = m[:, i, 0, None] * ct + m[:, i, 1, None] * st  # (b, 36)
        P = np.empty((b, 1 + 36 * 17), dtype=DTYPE)
        P[:, 0] = m[:, i, 2] + cc[:, i]  # the pole
        Q = P[:, 1:].reshape(b, 36, 17)
        np.multiply(ring[:, :, None], sp, out=Q)
        Q += (m[:, i, 2, None] * cp + cc[:, i, None])[:, None, :]
        planes.append(P)
    X, Y, Z = planes
    behind = None if all_front else Z.min(1) <= 0
    with np.errstate(divide="ignore", invalid="ignore"):  # unfitted rows are all zero
        np.divide(1.0, Z, out=Z)
        x = np.multiply(X, Z, out=X)
        y = np.multiply(Y, Z, out=Y)
    r2 = np.multiply(x, x, out=Z)
    r2 += y * y
    beyond = None if all_in_field else r2.max(1) > r2_max
    xd, yd = _distort32(x, y, r2, d)
    blo = np.empty((b, 2))
    bhi = np.empty((b, 2))
    if np.any(k[:, 0, 1] != 0):  # skew: u mixes xd and yd
        u = k[:, 0, 0, None] * xd + k[:, 0, 1, None] * yd
        blo[:, 0], bhi[:, 0] = u.min(1) + k[:, 0, 2], u.max(1) + k[:, 0, 2]
    else:  # u = fx xd + cx is monotonic in xd: scale the extremes only
        _extremes(xd.min(1), xd.max(1), k[:, 0, 0], k[:, 0, 2], blo[:, 0], bhi[:, 0])
    _extremes(yd.min(1), yd.max(1), k[:, 1, 1], k[:, 1, 2], blo[:, 1], bhi[:, 1])
    return blo, bhi, behind, beyond


def _centre_pixels(c, dist, K) -> tuple:
    """``(u, v)``: the helmet centre ``c`` (camera frame) in pixels, through the lens model."""
    with np.errstate(divide="ignore", invalid="ignore"):
        cx, cy = c[:, 0] / c[:, 2], c[:, 1] / c[:, 2]
    cxd, cyd = distort(cx, cy, dist)
    cu = K[:, 0, 0] * cxd + K[:, 0, 1] * cyd + K[:, 0, 2]
    cv = K[:, 1, 1] * cyd + K[:, 1, 2]
    return cu, cv


def _boxes(lo, hi, W, H, p, flags) -> tuple:
    """``(bbox, reason, detail)``: the extremes clamped to the image and the preset's box rules applied.

    ``flags = (behind, beyond, fitted, centre_in)``; a row gets its most basic failure's reason.
    """
    behind, beyond, fitted, centre_in = flags
    x0 = np.maximum(lo[:, 0], 0.0)
    y0 = np.maximum(lo[:, 1], 0.0)
    x1 = np.minimum(hi[:, 0], W)
    y1 = np.minimum(hi[:, 1], H)
    w = x1 - x0
    h = y1 - y0
    bbox = np.stack([x0, y0, w, h], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        aspect = np.maximum(w / h, h / w)
    empty = ~((w > 0) & (h > 0))
    aspect_bad = (aspect > p.max_aspect) if p.aspect_inclusive else (aspect >= p.max_aspect)
    side_bad = w >= p.max_side_fraction * W
    if p.check_height:
        side_bad |= h >= p.max_side_fraction * H
    n = len(lo)
    reason = np.full(n, "", dtype=object)
    detail = np.full(n, "", dtype=object)
    op = ">" if p.aspect_inclusive else ">="
    # assign in reverse priority so the most basic failure wins
    _set(reason, detail, ~empty & side_bad, "box rejected", f"a side >= {p.max_side_fraction:g} x image")
    _set(reason, detail, ~empty & aspect_bad, "box rejected", f"aspect ratio {op} {p.max_aspect:g}")
    _set(reason, detail, empty, "outside image", "clamped box is empty")
    _set(reason, detail, beyond, "outside image", "helmet beyond the lens model's field")
    _set(reason, detail, ~centre_in, "outside image", "head centre outside the image")
    _set(reason, detail, behind, "behind camera", "helmet reaches behind the camera")
    _set(reason, detail, ~fitted, "no fit", "no similarity fit")
    return bbox, reason, detail


def _extremes(amin, amax, scale, offset, lo, hi) -> None:
    """min/max of ``scale * a + offset`` from a's min and max (per-row scale of any sign)."""
    e0 = scale * amin + offset
    e1 = scale * amax + offset
    lo[...] = np.minimum(e0, e1)
    hi[...] = np.maximum(e0, e1)


def _distort32(x, y, r2, d):
    """OpenCV's distortion in place on float32 planes (``d`` per row, (b, 5)); returns (xd, yd).

    xd = x f + 2 p1 x y + p2 (r2 + 2 x^2), yd = y f + p1 (r2 + 2 y^2) + 2 p2 x y, written as
    xd = x g + p2 r2 and yd = y g + p1 r2 with g = f + 2 p1 y + 2 p2 x.
    """
    if isinstance(d, tuple):  # one coefficient per element (flat layout)
        k1, k2, p1, p2, k3 = d
    else:
        k1, k2, p1, p2, k3 = (d[:, j, None] for j in range(5))
    g = r2 * k3
    g += k2
    g *= r2
    g += k1
    g *= r2
    g += 1.0
    g += (2.0 * p1) * y
    g += (2.0 * p2) * x
    xd = np.multiply(x, g, out=x)
    xd += p2 * r2
    yd = np.multiply(y, g, out=y)
    yd += p1 * r2
    return xd, yd


# ------------------------------------------------------------------ fast path
#: rows whose helmet subtends less than this (degrees of half-angle) use the fast path
FAST_MAX_ANGLE = 9.0
#: grid points within this angle of a tangent point are projected (measured: the grid extreme is
#: always within 15 degrees of the tangent point of the distortion-linearised pencil for helmets under
#: 9 degrees; the table adds the bin's half diagonal)
FAST_NEIGHBOURHOOD = 15.0
FAST_BIN = 2.0  # degrees, bins of tangent-point directions in the lookup table
FAST_BLOCK_ROWS = 2048
FAST = True
_TABLE: dict = {}


def _grid_angles():
    """theta, phi (radians) of the 613 distinct helmet grid points, pole first (the slow path's order)."""
    theta = np.deg2rad(np.arange(0, 360, 10, dtype=np.float64))
    phi = np.deg2rad(np.arange(10, 180, 10, dtype=np.float64))
    th = np.concatenate([[0.0], np.repeat(theta, 17)])
    ph = np.concatenate([[0.0], np.tile(phi, 36)])
    return th, ph


def _table():
    """CSR lookup: for each (theta, phi) bin of a tangent direction, the grid points near it.

    The grid is invariant under theta turns of 10 degrees, so the neighbourhoods of the first
    10 degrees of bins are computed and the others are the same index sets turned.
    """
    if _TABLE:
        return _TABLE
    th, ph = _grid_angles()
    U = np.stack([np.cos(th) * np.sin(ph), np.sin(th) * np.sin(ph), np.cos(ph)], 1)
    per10 = int(round(10 / FAST_BIN))
    nt, nphi = 36 * per10, int(round(180 / FAST_BIN))
    bt = np.deg2rad((np.arange(per10) + 0.5) * FAST_BIN)
    bp = np.deg2rad((np.arange(nphi) + 0.5) * FAST_BIN)
    BT, BP = np.meshgrid(bt, bp, indexing="ij")
    B = np.stack([np.cos(BT) * np.sin(BP), np.sin(BT) * np.sin(BP), np.cos(BP)], -1)  # (per10, nphi, 3)
    cosr = np.cos(np.deg2rad(FAST_NEIGHBOURHOOD + FAST_BIN))  # a bin is within FAST_BIN/sqrt(2) of its centre
    near0 = np.einsum("tpk,gk->tpg", B, U) >= cosr  # (per10, nphi, 613)
    pole, ring = near0[..., :1], near0[..., 1:].reshape(per10, nphi, 36, 17)
    # bin (10 k + t0) sees the neighbourhood of bin t0 turned by k steps of theta
    ring_all = np.stack([np.roll(ring, k, axis=2) for k in range(36)], 0)  # (36, per10, nphi, 36, 17)
    near = np.concatenate(
        [np.broadcast_to(pole, (36,) + pole.shape), ring_all.reshape(36, per10, nphi, -1)], -1
    ).reshape(nt * nphi, -1)
    counts = near.sum(1)
    _TABLE.update(
        indices=np.nonzero(near)[1].astype(np.int32),
        offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        counts=counts.astype(np.int64),
        nt=nt,
        nphi=nphi,
        ct=np.cos(th).astype(DTYPE),
        st=np.sin(th).astype(DTYPE),
        sp=np.sin(ph).astype(DTYPE),
        cp=np.cos(ph).astype(DTYPE),
    )
    _TABLE["sp"][0] = 0.0  # the pole exactly (the slow path computes it as m2 + c)
    _TABLE["cp"][0] = 1.0
    return _TABLE


def _fast_extremes(M, c32, d32, K, Rtot, c, rho, d64):
    """Box extremes (lo, hi), each (b, 2), projecting only grid points near the tangent points.

    The extreme of ``u = fx xd + cx`` over the sphere lies where a plane of the pencil
    ``a x + b y = k z`` (``(a, b)`` the row of the distortion Jacobian at the helmet centre, so the
    pencil follows the lens) touches the sphere; likewise for ``v``. Only grid points within
    :data:`FAST_NEIGHBOURHOOD` of those four points are projected, with the slow path's float32
    arithmetic.
    """
    T = _table()
    b = len(c)
    # normalised coordinates of the centre and the distortion Jacobian there
    x0, y0 = c[:, 0] / c[:, 2], c[:, 1] / c[:, 2]
    k1, k2, p1, p2, k3 = (d64[:, j] for j in range(5))
    r2 = x0 * x0 + y0 * y0
    f = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    fp = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)
    jxx = f + 2.0 * x0 * x0 * fp + 2.0 * p1 * y0 + 6.0 * p2 * x0
    jxy = 2.0 * x0 * y0 * fp + 2.0 * p1 * x0 + 2.0 * p2 * y0
    jyx = 2.0 * x0 * y0 * fp + 2.0 * p1 * x0 + 2.0 * p2 * y0
    jyy = f + 2.0 * y0 * y0 * fp + 6.0 * p1 * y0 + 2.0 * p2 * x0
    cz = c[:, 2]
    den = cz * cz - rho * rho
    dirs = []
    for a_, b_ in ((jxx, jxy), (jyx, jyy)):
        q = a_ * c[:, 0] + b_ * c[:, 1]
        root = rho * np.sqrt(np.maximum((a_ * a_ + b_ * b_) * den + q * q, 0.0))
        for sign in (1.0, -1.0):
            k = (q * cz + sign * root) / den
            nrm = np.stack([a_, b_, -k], 1)
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            w = -np.sign(np.einsum("ni,ni->n", nrm, c))[:, None] * nrm
            dirs.append(np.einsum("nji,nj->ni", Rtot, w))  # into the helmet's own frame
    D = np.stack(dirs, 0)  # (4, b, 3): u max, u min, v max, v min
    th = np.mod(np.arctan2(D[..., 1], D[..., 0]), 2 * np.pi)
    ph = np.arccos(np.clip(D[..., 2], -1.0, 1.0))
    ti = np.minimum((np.rad2deg(th) / FAST_BIN).astype(np.int64), T["nt"] - 1)
    pi = np.minimum((np.rad2deg(ph) / FAST_BIN).astype(np.int64), T["nphi"] - 1)
    bins = (ti * T["nphi"] + pi).reshape(-1)  # extreme-major, then row
    counts = T["counts"][bins]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    total = int(counts.sum())
    flat = np.arange(total) - np.repeat(starts - T["offsets"][bins], counts)
    g = T["indices"][flat]
    ct, st, sp, cp = T["ct"][g], T["st"][g], T["sp"][g], T["cp"][g]
    # per-row parameters repeated into contiguous per-element columns (no strided access)
    params = np.concatenate([M.reshape(b, 9), c32, d32], 1).T  # (17, b)
    col = [np.repeat(np.tile(params[j], 4), counts) for j in range(17)]
    planes = []
    for i in range(3):
        ring = col[3 * i] * ct + col[3 * i + 1] * st
        planes.append(ring * sp + (col[3 * i + 2] * cp + col[9 + i]))
    X, Y, Z = planes
    np.divide(1.0, Z, out=Z)
    x = np.multiply(X, Z, out=X)
    y = np.multiply(Y, Z, out=Y)
    rr = np.multiply(x, x, out=Z)
    rr += y * y
    xd, yd = _distort32(x, y, rr, tuple(col[12:17]))
    seg = starts.reshape(4, b)
    lo = np.empty((b, 2))
    hi = np.empty((b, 2))
    ends = [int(seg[e + 1, 0]) if e < 3 else total for e in range(4)]
    xmax = np.maximum.reduceat(xd[seg[0, 0] : ends[0]], seg[0] - seg[0, 0])
    xmin = np.minimum.reduceat(xd[seg[1, 0] : ends[1]], seg[1] - seg[1, 0])
    ymax = np.maximum.reduceat(yd[seg[2, 0] : ends[2]], seg[2] - seg[2, 0])
    ymin = np.minimum.reduceat(yd[seg[3, 0] : ends[3]], seg[3] - seg[3, 0])
    _extremes(xmin, xmax, K[:, 0, 0], K[:, 0, 2], lo[:, 0], hi[:, 0])
    _extremes(ymin, ymax, K[:, 1, 1], K[:, 1, 2], lo[:, 1], hi[:, 1])
    return lo, hi


def _set(reason, detail, mask, r, d) -> None:
    reason[mask] = r
    detail[mask] = d
