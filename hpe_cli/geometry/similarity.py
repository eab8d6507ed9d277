"""Batched similarity fit (scale, rotation, translation) between point sets.

The closed form is Umeyama's (1991), which for 3-D points is the same answer
as Horn's (1987) quaternion method: centre both sets, take the SVD of their
cross-covariance, force a proper rotation with the sign of the determinant,
then read the scale off the singular values. Every face of a whole chunk of
frames is fitted in one ``numpy.linalg.svd`` call on an ``(N, 3, 3)`` stack.
"""

from __future__ import annotations

import numpy as np

#: a fit needs three non-collinear pairs; fewer give NaN
MIN_FIT_PAIRS = 3


def fit_similarity(src, dst, mask=None) -> dict:
    """Fit ``dst ~= scale * R @ src + t`` for many point sets at once.

    Parameters
    ----------
    src, dst : array_like, shape (N, P, 3)
        Corresponding points (any length unit; ``dst`` sets the output unit).
        Non-finite coordinates make a pair unusable.
    mask : array_like of bool, shape (N, P), optional
        Which pairs to use (all finite pairs by default).

    Returns
    -------
    dict
        ``scale`` (N,) float, > 0; ``R`` (N, 3, 3) proper rotations
        (det +1); ``t`` (N, 3) in ``dst`` units; ``rmse`` (N,) root mean
        square distance between ``scale * R @ src + t`` and ``dst`` over the
        used pairs, in ``dst`` units; ``n_pairs`` (N,) int, pairs used.
        Rows with fewer than 3 usable pairs, or with all used ``src`` points
        coincident or collinear, get NaN in ``scale``, ``R``, ``t`` and
        ``rmse`` (``n_pairs`` is still reported).

    Notes
    -----
    With centred sets ``a_i = src_i - mean(src)``, ``b_i = dst_i - mean(dst)``,
    ``S = sum b_i a_i^T = U D V^T``, the rotation is ``U diag(1, 1, d) V^T``
    with ``d = sign(det(U V^T))``, the scale is
    ``trace(diag(D) diag(1, 1, d)) / sum |a_i|^2`` and
    ``t = mean(dst) - scale * R @ mean(src)``. This minimises the summed squared
    residual over all similarities (Umeyama 1991, Lemma and Theorem).
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.ndim != 3 or src.shape[-1] != 3 or dst.shape != src.shape:
        raise ValueError(f"expected src and dst of the same shape (N, P, 3), got {src.shape} and {dst.shape}")
    use = np.isfinite(src).all(-1) & np.isfinite(dst).all(-1)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != src.shape[:2]:
            raise ValueError(f"expected mask of shape {src.shape[:2]}, got {mask.shape}")
        use &= mask
    w = use.astype(np.float64)
    n = w.sum(1)
    n_safe = np.maximum(n, 1.0)
    # zero the unused points so NaN never enters a sum (NaN * 0 is NaN)
    s0 = np.where(use[..., None], src, 0.0)
    d0 = np.where(use[..., None], dst, 0.0)
    mu_s = s0.sum(1) / n_safe[:, None]
    mu_d = d0.sum(1) / n_safe[:, None]
    a = (s0 - mu_s[:, None, :]) * w[..., None]
    b = (d0 - mu_d[:, None, :]) * w[..., None]
    cov = np.einsum("npi,npj->nij", b, a)
    U, D, Vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    d = np.where(d == 0, 1.0, d)
    U[:, :, 2] *= d[:, None]
    R = U @ Vt
    var_a = np.einsum("npi,npi->n", a, a)
    trace = D[:, 0] + D[:, 1] + d * D[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = trace / var_a
    t = mu_d - scale[:, None] * np.einsum("nij,nj->ni", R, mu_s)
    fitted = scale[:, None, None] * np.einsum("nij,npj->npi", R, s0) + t[:, None, :]
    res = np.where(use, np.einsum("npi,npi->np", fitted - d0, fitted - d0), 0.0)
    rmse = np.sqrt(res.sum(1) / n_safe)
    # a rank-1 (collinear) source set leaves the rotation about that line free
    tol = 1e-12 * np.maximum(D[:, 0], np.finfo(float).tiny)
    bad = (n < MIN_FIT_PAIRS) | ~(var_a > 0) | (D[:, 1] <= tol) | ~np.isfinite(scale) | ~(scale > 0)
    if bad.any():
        scale = np.where(bad, np.nan, scale)
        R = np.where(bad[:, None, None], np.nan, R)
        t = np.where(bad[:, None], np.nan, t)
        rmse = np.where(bad, np.nan, rmse)
    return {"scale": scale, "R": R, "t": t, "rmse": rmse, "n_pairs": n.astype(np.int64)}
