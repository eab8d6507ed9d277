"""Consistency of labels with each other: views of one head, frames of one sequence, one score.

Pure numpy on whole columns; groups are runs of a sorted order, reduced with
``numpy.add.reduceat`` (no Python loop per row or per group).

Views (:func:`view_consensus`)
    The labels of one head at one time seen by several calibrated cameras, mapped
    back to the world (``W = cam_R.T @ E @ A`` for a label ``A = E @ cam_R @
    R_head``, ``E = diag(1, -1, -1)``), must agree. The consensus of a group is its
    chordal L1 mean (the geometric median of the matrices in the Frobenius norm,
    projected onto SO(3); Hartley, Trumpf, Dai & Li, "Rotation averaging", IJCV
    2013, section 6.2), found by Weiszfeld iterations: robust to a minority of bad
    views. Each label's angle to it is its view disagreement; its offset, ``A @
    (E cam_R C).T`` as a rotation vector in the camera's canonical frame, is what a
    wrong camera rotation adds to every label of that camera.

Time (:func:`temporal_jumps`)
    A label is compared with the geodesic interpolation (slerp) of its previous and
    next labels at its frame: a steady turn lies on it, a label that jumps away and
    back does not. The deviation is divided by the frame distance to the nearer
    neighbour (degrees per frame). The smallest over the neighbour pairs one or two
    rows away on each side is kept, so the neighbours of a one-frame glitch are not
    flagged with it (a glitch of two consecutive frames is therefore not seen).

Score (:func:`fit_expected_landmark_angle`, :func:`combined_score`)
    Each check's angle is divided by the disagreement expected for it, so rows of
    different datasets and yaws rank together; the row's score is the largest
    ratio over the checks that apply to it (NaN when none does). The expected
    landmark angle grows with |yaw| (landmark fits are noisier in profile); it is
    fitted to the table's own medians per |yaw| bin when it has enough rows.
"""

from __future__ import annotations

import numpy as np

from ..rotation.distances import geodesic_deg
from ..rotation.storage import matrix_to_rotvec, rotvec_to_matrix
from .sketch import EXACT_CAP, BinnedMedians

#: Weiszfeld iterations of the chordal L1 mean (each a projection onto SO(3))
L1_ITERATIONS = 20
#: floor of a Weiszfeld distance (Frobenius), so that a view equal to the mean keeps a finite weight
L1_EPS = 1e-9

#: expected landmark-to-label angle at yaw 0 and its growth to yaw 90 (degrees):
#: ``LM_EXPECTED_0 + LM_EXPECTED_90 * (|yaw| / 90)^2``. Set from the real samples: the 16 AFLW2000-3D
#: faces (21 manual points) have median 6.7 deg, frontal faces 5-7 deg, |yaw| 55-71 deg faces 10-30 deg;
#: the 300W-LP face (68 points, yaw -44) 3.7 deg.
LM_EXPECTED_0 = 5.0
LM_EXPECTED_90 = 8.0
#: expected disagreement of calibrated views (degrees): labels made with one calibration agree to
#: float precision; a camera rotated by 1 deg is already an error worth naming
VIEW_EXPECTED = 1.0
#: a score above this marks a suspect
SUSPECT_SCORE = 3.0


def group_starts(codes_sorted) -> np.ndarray:
    """Start index of each run of equal values in a sorted ``(N,)`` or ``(N, k)`` code array."""
    c = np.asarray(codes_sorted)
    if len(c) == 0:
        return np.zeros(0, dtype=np.intp)
    change = c[1:] != c[:-1]
    if change.ndim == 2:
        change = change.any(1)
    return np.concatenate([[0], np.flatnonzero(change) + 1]).astype(np.intp)


def _project_so3(M) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def chordal_l1_mean(R, starts, iterations: int = L1_ITERATIONS) -> np.ndarray:
    """Chordal L1 mean of each group of rotations.

    Parameters
    ----------
    R : ndarray, shape (N, 3, 3)
        Rotations sorted by group.
    starts : ndarray of int, shape (G,)
        First row of each group (:func:`group_starts`).

    Returns
    -------
    ndarray, shape (G, 3, 3)
        The rotation minimising ``sum_i ||R_i - C||_F`` per group (Weiszfeld,
        started from the chordal L2 mean).
    """
    R = np.asarray(R, dtype=np.float64)
    flat = R.reshape(len(R), 9)
    sizes = np.diff(np.append(starts, len(R)))
    C = _project_so3(np.add.reduceat(flat, starts, axis=0).reshape(-1, 3, 3))
    for _ in range(iterations):
        d = np.linalg.norm(flat - np.repeat(C.reshape(-1, 9), sizes, axis=0), axis=1)
        w = 1.0 / np.maximum(d, L1_EPS)
        C = _project_so3(np.add.reduceat(flat * w[:, None], starts, axis=0).reshape(-1, 3, 3))
    return C


def view_consensus(A, cam_R, starts) -> dict:
    """Each label's disagreement with the consensus of its group of views.

    Parameters
    ----------
    A : ndarray, shape (N, 3, 3)
        Labels (300W-LP active matrices, each in its camera's canonical frame),
        sorted by group (one head at one time).
    cam_R : ndarray, shape (N, 3, 3)
        World -> camera rotation of each row's camera (OpenCV camera frame).
    starts : ndarray of int, shape (G,)

    Returns
    -------
    dict
        ``angle`` (N,) degrees to the group's consensus; ``offset`` (N, 3), the
        rotation vector (degrees) of ``A @ Â.T`` in the camera's canonical frame,
        ``Â = E @ cam_R @ C`` the consensus seen by that camera; ``size`` (N,) the
        group size; ``consensus`` (G, 3, 3) head rotations in the world.
    """
    E = np.diag([1.0, -1.0, -1.0])
    A = np.asarray(A, dtype=np.float64)
    cam_R = np.asarray(cam_R, dtype=np.float64)
    W = np.swapaxes(cam_R, 1, 2) @ (E @ A)
    C = chordal_l1_mean(W, starts)
    sizes = np.diff(np.append(starts, len(A)))
    Cr = np.repeat(C, sizes, axis=0)
    expect = E @ cam_R @ Cr
    off = A @ np.swapaxes(expect, 1, 2)
    return {
        "angle": geodesic_deg(Cr, W),
        "offset": np.rad2deg(matrix_to_rotvec(off)),
        "size": np.repeat(sizes, sizes),
        "consensus": C,
    }


def camera_offsets(offset, camera_codes, min_deg: float = VIEW_EXPECTED, z: float = 3.0) -> dict:
    """Each camera's median offset and whether it is significant.

    Parameters
    ----------
    offset : ndarray, shape (N, 3)
        Rotation vectors in degrees (:func:`view_consensus`).
    camera_codes : ndarray of int, shape (N,)
    min_deg : float
        An offset is named when its angle exceeds this (degrees) ...
    z : float
        ... and ``z`` times its standard error (1.4826 MAD / sqrt(n) per axis).

    Returns
    -------
    dict
        ``codes`` (C,), ``n`` (C,), ``median`` (C, 3) degrees, ``angle`` (C,)
        degrees, ``significant`` (C,) bool.
    """
    offset = np.asarray(offset, dtype=np.float64)
    order = np.argsort(camera_codes, kind="stable")
    codes = np.asarray(camera_codes)[order]
    starts = group_starts(codes)
    sizes = np.diff(np.append(starts, len(codes)))
    o = offset[order]
    # medians per camera: sort each axis within its camera (cameras are few; rows are many)
    med = np.empty((len(starts), 3))
    mad = np.empty((len(starts), 3))
    key = np.repeat(np.arange(len(starts)), sizes)
    for k in range(3):
        srt = o[np.lexsort((o[:, k], key)), k]
        med[:, k] = _run_median(srt, starts, sizes)
        dev = np.abs(o[:, k] - np.repeat(med[:, k], sizes))
        mad[:, k] = _run_median(dev[np.lexsort((dev, key))], starts, sizes)
    angle = np.linalg.norm(med, axis=1)
    se = 1.4826 * np.linalg.norm(mad, axis=1) / np.sqrt(sizes)
    return {
        "codes": codes[starts],
        "n": sizes,
        "median": med,
        "angle": angle,
        "significant": (angle > min_deg) & (angle > z * se),
    }


def _run_median(sorted_values, starts, sizes) -> np.ndarray:
    lo = starts + (sizes - 1) // 2
    hi = starts + sizes // 2
    return 0.5 * (sorted_values[lo] + sorted_values[hi])


def temporal_jumps(A, frames, starts, max_gap: int) -> dict:
    """How far each label leaves the slerp of its neighbours, per frame.

    Parameters
    ----------
    A : ndarray, shape (N, 3, 3)
        Labels sorted by track (sequence, person, camera), then frame.
    frames : ndarray of int, shape (N,)
    starts : ndarray of int
        First row of each track.
    max_gap : int
        Neighbours further than this many frames are not used.

    Returns
    -------
    dict
        ``deviation`` (N,) degrees between the label and the slerp of its
        neighbours at its frame; ``rate`` (N,) that over the frame distance to
        the nearer neighbour (degrees per frame); NaN for rows without a
        neighbour on both sides within ``max_gap`` frames.
    """
    A = np.asarray(A, dtype=np.float64)
    f = np.asarray(frames, dtype=np.int64)
    N = len(A)
    dev = np.full(N, np.nan)
    rate = np.full(N, np.nan)
    if N == 0:
        return {"deviation": dev, "rate": rate}
    inner = np.ones(N, dtype=bool)
    inner[starts] = False  # first of a track
    inner[np.append(starts[1:], N) - 1] = False  # last of a track
    i = np.flatnonzero(inner)
    have = np.zeros(len(i), dtype=bool)
    track = np.repeat(np.arange(len(starts)), np.diff(np.append(starts, N)))
    # the neighbours one and two rows away on each side: a glitch next door must not flag a good label
    best = np.full(len(i), np.nan)
    near = np.ones(len(i))
    for a, b in ((1, 1), (2, 1), (1, 2), (2, 2)):
        lo, hi = i - a, i + b
        ok = (lo >= 0) & (hi < N)
        lo_c, hi_c = np.clip(lo, 0, N - 1), np.clip(hi, 0, N - 1)
        ok &= (track[lo_c] == track[i]) & (track[hi_c] == track[i])
        g1 = f[i] - f[lo_c]
        g2 = f[hi_c] - f[i]
        ok &= (g1 > 0) & (g2 > 0) & (g1 <= max_gap) & (g2 <= max_gap)
        if (a, b) == (1, 1):
            have = ok  # the row needs its nearest neighbour on both sides
            near = np.maximum(np.minimum(g1, g2), 1)  # the rate is per frame to the nearer neighbour
        j = np.flatnonzero(ok & have)
        if not len(j):
            continue
        P, Nx = A[lo_c[j]], A[hi_c[j]]
        tau = g1[j] / (g1[j] + g2[j])
        rel = matrix_to_rotvec(np.swapaxes(P, 1, 2) @ Nx)
        interp = P @ rotvec_to_matrix(rel * tau[:, None])
        d = geodesic_deg(interp, A[i[j]])
        best[j] = np.fmin(best[j], d)
    dev[i[have]] = best[have]
    rate[i[have]] = best[have] / near[have]
    return {"deviation": dev, "rate": rate}


def yaw_deg(A) -> np.ndarray:
    """300W-LP yaw of canonical matrices, degrees in [-90, 90]: ``asin(-A[0, 2])``."""
    return np.rad2deg(np.arcsin(np.clip(-np.asarray(A)[..., 0, 2], -1.0, 1.0)))


def expected_landmark_angle(abs_yaw_deg, a: float = LM_EXPECTED_0, b: float = LM_EXPECTED_90) -> np.ndarray:
    """Expected landmark-to-label angle (degrees) at ``|yaw|`` degrees: ``a + b (|yaw| / 90)^2``."""
    t = np.clip(np.asarray(abs_yaw_deg, dtype=np.float64), 0.0, 90.0) / 90.0
    return a + b * t * t


#: landmark-checked rows needed to fit the expected angle to the data (fewer: the constants above)
MIN_FIT_ROWS = 200
#: |yaw| bins of the fit (degrees) and the rows a bin needs
FIT_EDGES = np.array([0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 180.0])
FIT_MIN_BIN = 10
#: the fitted expectation never goes below this (degrees): landmarks are not more precise than that
FIT_FLOOR_DEG = 1.0


def fit_expected_landmark_angle(abs_yaw_deg, angle_deg) -> dict:
    """Fit ``expected(|yaw|) = a + b (|yaw| / 90)^2`` to the median angle per |yaw| bin (robust to outliers).

    Parameters
    ----------
    abs_yaw_deg, angle_deg : array_like, shape (N,)
        Labels' |yaw| and their landmark angles (NaN: not checked, ignored).

    Returns
    -------
    dict
        ``a``, ``b`` (degrees), ``source`` (``"fitted on N rows"`` or ``"constants"``
        when fewer than :data:`MIN_FIT_ROWS` rows or no two bins of
        :data:`FIT_MIN_BIN` rows). The medians of 15-degree bins make the fit
        robust to up to half of a bin's labels being wrong; weighted least
        squares over the bins, then ``a >= FIT_FLOOR_DEG`` and ``b >= 0``.
    """
    y = np.asarray(abs_yaw_deg, dtype=np.float64)
    v = np.asarray(angle_deg, dtype=np.float64)
    ok = np.isfinite(y) & np.isfinite(v)
    if ok.sum() < MIN_FIT_ROWS:
        return {"a": LM_EXPECTED_0, "b": LM_EXPECTED_90, "source": "constants"}
    y, v = np.minimum(y[ok], 90.0), v[ok]
    k = np.clip(np.searchsorted(FIT_EDGES, y, side="right") - 1, 0, len(FIT_EDGES) - 2)
    t, m, w = [], [], []
    for b in range(len(FIT_EDGES) - 1):  # six bins, not rows
        sel = k == b
        if sel.sum() >= FIT_MIN_BIN:
            t.append(np.median((y[sel] / 90.0) ** 2))
            m.append(np.median(v[sel]))
            w.append(np.sqrt(sel.sum()))
    return _fit_bins(t, m, w, int(ok.sum()))


def _fit_bins(t, m, w, n: int) -> dict:
    """Weighted least squares of ``m = a + b t`` over the bins (``a >= FIT_FLOOR_DEG``, ``b >= 0``)."""
    if len(t) < 2:
        return {"a": LM_EXPECTED_0, "b": LM_EXPECTED_90, "source": "constants"}
    t, m, w = map(np.asarray, (t, m, w))
    X = np.stack([np.ones_like(t), t], 1) * w[:, None]
    (a, b), *_ = np.linalg.lstsq(X, m * w, rcond=None)
    b = max(float(b), 0.0)
    a = max(float(np.average(m - b * t, weights=w)) if b == 0.0 else float(a), FIT_FLOOR_DEG)
    return {"a": a, "b": b, "source": f"fitted on {n} rows"}


#: resolution of the streamed |yaw| and landmark-angle medians once a table has more than
#: :data:`hpe_cli.metrics.sketch.EXACT_CAP` landmark-checked rows (degrees)
FIT_RESOLUTION_DEG = 0.01


def expected_angle_sketch(exact_cap=None):
    """The bounded-memory collector of ``(|yaw|, landmark angle)`` pairs :func:`fit_expected_streamed` fits."""

    cap = EXACT_CAP if exact_cap is None else exact_cap
    return BinnedMedians(FIT_EDGES, 90.0, 180.0, FIT_RESOLUTION_DEG, FIT_RESOLUTION_DEG, cap)


def fit_expected_streamed(sketch) -> dict:
    """:func:`fit_expected_landmark_angle` of the pairs added to ``sketch`` (:func:`expected_angle_sketch`).

    Exact (the same result) while the sketch holds every pair; beyond, the
    medians per |yaw| bin come from histograms of :data:`FIT_RESOLUTION_DEG`
    degrees, and the median ``t`` of a bin is ``(median |yaw| / 90)^2``.
    """
    vals = sketch.values()
    if vals is not None:
        return fit_expected_landmark_angle(*vals)
    if sketch.n < MIN_FIT_ROWS:
        return {"a": LM_EXPECTED_0, "b": LM_EXPECTED_90, "source": "constants"}
    t, m, w = [], [], []
    for x, y in zip(sketch.x, sketch.y):  # six bins, not rows
        if x.n >= FIT_MIN_BIN:
            t.append((float(x.percentile(50)[0]) / 90.0) ** 2)
            m.append(float(y.percentile(50)[0]))
            w.append(np.sqrt(x.n))
    return _fit_bins(t, m, w, int(sketch.n))


def combined_score(*ratios) -> np.ndarray:
    """The largest of the checks' ratios per row, NaN where no check applied."""
    stack = np.stack([np.asarray(r, dtype=np.float64) for r in ratios])
    with np.errstate(invalid="ignore"):
        any_ok = np.isfinite(stack).any(0)
        out = np.where(any_ok, np.nanmax(np.where(np.isfinite(stack), stack, -np.inf), axis=0), np.nan)
    return out
