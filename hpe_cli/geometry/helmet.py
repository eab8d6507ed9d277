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
    pts = np.stack(np.broadcast_arrays(np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi),
                                       np.cos(phi) + 0 * theta), axis=-1).reshape(-1, 3)
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


def helmet_boxes(scale, R, t, K, dist, cam_R, cam_t, width, height, preset="whenet", *,
                 return_centre: bool = False) -> dict:
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
    R = _per_row(R, n, (3, 3))
    t = _per_row(t, n, (3,))
    K = _per_row(K, n, (3, 3))
    dist = np.asarray(dist, dtype=np.float64)
    dist = _per_row(dist if dist.shape[-1] == 5 else np.concatenate(
        [dist, np.zeros(dist.shape[:-1] + (5 - dist.shape[-1],))], -1), n, (5,))
    cam_R = _per_row(cam_R, n, (3, 3))
    cam_t = _per_row(cam_t, n, (3,))
    W = np.broadcast_to(np.asarray(width, dtype=np.float64), (n,))
    H = np.broadcast_to(np.asarray(height, dtype=np.float64), (n,))

    # The sphere is a theta x phi grid: for a rotation-scale M, M @ u(theta, phi) =
    # sin(phi) (cos(theta) M[:, 0] + sin(theta) M[:, 1]) + cos(phi) M[:, 2], so each
    # camera coordinate costs one multiply-add per point. The 36 points at phi = 0
    # coincide (the pole) and are projected once.
    theta = np.deg2rad(np.arange(0, 360, 10, dtype=np.float64))
    phi = np.deg2rad(np.arange(10, 180, 10, dtype=np.float64))
    ct, st, sp, cp = np.cos(theta), np.sin(theta), np.sin(phi), np.cos(phi)
    centre_ref = np.asarray(p.offset, dtype=np.float64)

    # camera frame of a helmet point: M @ u + c, M = scale * radius * cam_R @ R,
    # c = cam_R @ (scale * R @ offset + t) + cam_t
    G = scale[:, None, None] * (cam_R @ R)
    M = p.radius * G
    c = np.einsum("nij,nj->ni", G, np.broadcast_to(centre_ref, (n, 3))) \
        + np.einsum("nij,nj->ni", cam_R, t) + cam_t
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
    rho = np.abs(scale) * p.radius
    dist_c = np.linalg.norm(c, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.arccos(np.clip(c[:, 2] / dist_c, -1.0, 1.0)) + np.arcsin(np.clip(rho / dist_c, 0.0, 1.0))
        safe_front = c[:, 2] - rho > 0
        safe_field = safe_front & (off < np.pi / 2) & (np.tan(np.minimum(off, 1.5)) ** 2 < r2_max)
    Mf32, cf32, dist32 = Mf.astype(DTYPE), cf.astype(DTYPE), dist.astype(DTYPE)
    ct, st, sp, cp = (a.astype(DTYPE) for a in (ct, st, sp, cp))
    for s in range(0, n, BLOCK_ROWS):
        sl = slice(s, min(s + BLOCK_ROWS, n))
        m, cc, d, k = Mf32[sl], cf32[sl], dist32[sl], K[sl]
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
        if not safe_front[sl].all():
            behind[sl] = Z.min(1) <= 0
        with np.errstate(divide="ignore", invalid="ignore"):  # unfitted rows are all zero
            np.divide(1.0, Z, out=Z)
            x = np.multiply(X, Z, out=X)
            y = np.multiply(Y, Z, out=Y)
        r2 = np.multiply(x, x, out=Z)
        r2 += y * y
        if not safe_field[sl].all():
            beyond[sl] = r2.max(1) > r2_max[sl]
        k1, k2, p1, p2, k3 = (d[:, j, None] for j in range(5))
        # OpenCV: xd = x f + 2 p1 x y + p2 (r2 + 2 x^2), yd = y f + p1 (r2 + 2 y^2) + 2 p2 x y,
        # which is xd = x g + p2 r2 and yd = y g + p1 r2 with g = f + 2 p1 y + 2 p2 x
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
        if np.any(k[:, 0, 1] != 0):  # skew: u mixes xd and yd
            u = k[:, 0, 0, None] * xd + k[:, 0, 1, None] * yd
            lo[sl, 0], hi[sl, 0] = u.min(1) + k[:, 0, 2], u.max(1) + k[:, 0, 2]
        else:  # u = fx xd + cx is monotonic in xd: scale the extremes only
            _extremes(xd, k[:, 0, 0], k[:, 0, 2], lo[sl, 0], hi[sl, 0])
        _extremes(yd, k[:, 1, 1], k[:, 1, 2], lo[sl, 1], hi[sl, 1])

    # the helmet centre, to tell "mostly outside" from "truncated by the border"
    with np.errstate(divide="ignore", invalid="ignore"):
        cx, cy = c[:, 0] / c[:, 2], c[:, 1] / c[:, 2]
    cxd, cyd = distort(cx, cy, dist)
    cu = K[:, 0, 0] * cxd + K[:, 0, 1] * cyd + K[:, 0, 2]
    cv = K[:, 1, 1] * cyd + K[:, 1, 2]
    centre_in = (cu >= 0) & (cu < W) & (cv >= 0) & (cv < H)

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
    invalid = behind | ~fitted
    bbox[invalid] = np.nan
    out = {"bbox": bbox, "ok": reason == "", "reason": reason, "detail": detail}
    if return_centre:
        out["centre"] = np.where(invalid[:, None], np.nan, np.stack([cu, cv], axis=1))
    return out


def _extremes(a, scale, offset, lo, hi) -> None:
    """min/max over axis 1 of ``scale * a + offset`` (per-row scale of any sign)."""
    e0 = scale * a.min(1) + offset
    e1 = scale * a.max(1) + offset
    lo[...] = np.minimum(e0, e1)
    hi[...] = np.maximum(e0, e1)


def _set(reason, detail, mask, r, d) -> None:
    reason[mask] = r
    detail[mask] = d
