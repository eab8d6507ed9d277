"""Remove a constant rotation offset; project matrices onto rotations (pure numpy).

``--align mean`` (hpe's own estimate, not a peer's) finds the one rotation
``Q`` that best maps the ground truth onto the predictions, ``P ~ Q @ G``:
the rotation nearest (Frobenius) to the arithmetic mean of ``P @ G.T`` over
ALL pairs, found by projecting that mean onto SO(3) with an SVD (the chordal
L2 mean). Predictions are then replaced by ``Q.T @ P``.

This is NOT opal23's alignment: opal23's ``Evaluator.align_predictions``
(pcr-upm/opal23_headpose@78c0c45 test/evaluator.py:95-129) iterates a
geodesic (Karcher) mean and leaves out the rows more than 90 degrees from
the identity; that one is the ``opal23-align`` protocol. The two agree for a
constant offset with small symmetric noise and no far-off rows.
"""

from __future__ import annotations

import numpy as np

from .rotation_errors import as_nested


def project_to_so3(M) -> np.ndarray:
    """The rotation nearest to the 3x3 matrix ``M`` (Frobenius norm), via SVD with det fixed to +1."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def project_to_so3_batch(M):
    """Nearest rotations (Frobenius) of ``(N, 3, 3)`` matrices and their distances ``||M - R||_F``.

    ``R = U diag(1, 1, det(U V^T)) V^T`` from the SVD ``M = U S V^T`` (det +1
    always). Rows that are not finite get the identity and distance NaN.
    """
    M = np.asarray(M, dtype=np.float64)
    finite = np.isfinite(M).all(axis=(1, 2))
    Mf = np.where(finite[:, None, None], M, np.eye(3))
    U, _, Vt = np.linalg.svd(Mf)
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    U[:, :, 2] *= d[:, None]
    R = U @ Vt
    dist = np.sqrt(((Mf - R) ** 2).sum(axis=(1, 2)))
    dist[~finite] = np.nan
    R[~finite] = np.eye(3)
    return R, dist


def mean_offset(P, G, mask=None) -> np.ndarray:
    """``Q = proj_SO3(mean_i P_i G_i^T)`` over the rows in ``mask`` (all when None).

    Parameters
    ----------
    P, G : ndarray (N, 3, 3) or nested list
        Predicted and true rotations in one frame.

    Returns
    -------
    ndarray (3, 3)
        A rotation; the identity when no row is selected.
    """
    P, G = as_nested(P), as_nested(G)
    M = np.zeros((3, 3))
    n = None
    for k in range(3):
        for l in range(3):
            v = P[k][0] * G[l][0] + P[k][1] * G[l][1] + P[k][2] * G[l][2]
            v = np.asarray(v, dtype=np.float64)
            if mask is not None:
                v = v[mask]
            n = v.size
            M[k, l] = v.mean() if v.size else (1.0 if k == l else 0.0)
    if not n:
        return np.eye(3)
    return project_to_so3(M)


def remove_offset(P, Q):
    """``Q.T @ P`` for every row, as a nested list (the aligned predictions)."""
    P = as_nested(P)
    Qt = np.asarray(Q, dtype=np.float64).T
    return [[Qt[k, 0] * P[0][j] + Qt[k, 1] * P[1][j] + Qt[k, 2] * P[2][j] for j in range(3)] for k in range(3)]
