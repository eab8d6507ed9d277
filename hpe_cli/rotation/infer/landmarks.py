"""3-D landmarks of faces: ranking the systems by the rotation residual of a fitted template."""

from __future__ import annotations

import numpy as np

from ..distances import geodesic_deg
from ..systems import ROLES, builtin_systems
from .core import (
    SEARCH_ROWS,
    builtin_canonical_by_candidate,
    builtin_names_by_candidate,
    candidate_matrices,
    candidates,
    rank_builtins,
)


# --------------------------------------------------------------------------- landmarks
def polar_rotation(M) -> np.ndarray:
    """Nearest proper rotation to each ``(..., 3, 3)`` matrix (Frobenius sense)."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


#: at least this many faces before a constant template offset is fitted per hypothesis
MIN_FACES_FOR_OFFSET = 8
#: largest constant template offset allowed (degrees): the template is frontal up to a small tilt
MAX_TEMPLATE_OFFSET_DEG = 15.0
#: a landmark answer is clear when the runner-up's RMS residual is at least this many times the winner's
CLEAR_SEPARATION = 2.0
#: ... and the winner's RMS residual is at most this (degrees)
POOR_RESIDUAL_DEG = 10.0


def _rms(res):
    return np.sqrt(np.mean(np.square(res), axis=-1))


def _landmark_residuals(G, R_obs, fit_offset: bool):
    """Geodesic residuals (C, N) of ``G @ Q`` against ``R_obs``; Q (C, 3, 3) the per-candidate offset."""
    if fit_offset:
        Q = polar_rotation(np.einsum("cnji,njk->cik", G, R_obs))
        # only a small tilt of the template is plausible; a large offset would hide a wrong frame
        big = geodesic_deg(Q, np.eye(3)) > MAX_TEMPLATE_OFFSET_DEG
        Q[big] = np.eye(3)
    else:
        Q = np.broadcast_to(np.eye(3), (G.shape[0], 3, 3))
    return geodesic_deg(np.matmul(G, Q[:, None]), R_obs[None]), Q


def infer_landmarks(
    pyr_deg,
    R_obs,
    *,
    roles=ROLES,
    fit_offset: bool | None = None,
    source: str = "<table>",
    row_ids=None,
    fit_rmse=None,
    fit_rmse_limit: float | None = None,
    seed: int = 0,
    name: str | None = None,
) -> dict:
    """Rank systems by how well their matrices from the labels explain observed rotations.

    Parameters
    ----------
    pyr_deg : array_like (N, 3)
        Labels in role order, degrees.
    R_obs : array_like (N, 3, 3)
        Observed active rotations in the canonical frame (e.g. a 68-point
        template fitted to each face, :mod:`hpe_cli.geometry.template`).
    fit_offset : bool, optional
        Fit one constant rotation ``Q`` per hypothesis (``R_obs ~ G(labels) @ Q``:
        the template's own tilt in the head frame, 3 parameters for all
        faces), used only when it is within :data:`MAX_TEMPLATE_OFFSET_DEG`
        (a larger one, such as the 180 deg turn that lets a mirrored face
        pass, is not a tilt). Default: only with at least
        :data:`MIN_FACES_FOR_OFFSET` faces.
    row_ids, fit_rmse : optional per-row identifiers and template-fit residuals for the report.
    fit_rmse_limit : float, optional
        When the median of ``fit_rmse`` is above it, the landmarks do not look
        like the template (a wrong landmark frame mirrors the face) and the
        verdict is ``poor`` whatever the residuals.

    Returns
    -------
    dict
        ``best`` (a built-in name whose labels-to-canonical map wins, or
        ``custom``), ``fit`` (``clear``, ``ambiguous`` or ``poor``),
        ``ranking`` (distinct functions by RMS residual, best first),
        ``hypotheses`` (each built-in's reading of the labels, and its stored
        matrix read as the active canonical rotation, grouped by function),
        ``per_face`` residuals in degrees for the winner.
    """
    pyr = np.asarray(pyr_deg, dtype=np.float64).reshape(-1, 3)
    R_obs = np.asarray(R_obs, dtype=np.float64).reshape(-1, 3, 3)
    ok = np.isfinite(pyr).all(1) & np.isfinite(R_obs).all((1, 2))
    rows = np.flatnonzero(ok)
    pyr, R_obs = pyr[ok], R_obs[ok]
    n = len(pyr)
    if n == 0:
        raise ValueError("no row has finite angles and a fitted rotation")
    if fit_offset is None:
        fit_offset = n >= MIN_FACES_FOR_OFFSET
    sc = _Scores(pyr, R_obs, fit_offset, seed)
    ranking = [sc.entry(k, roles) for k in sc.order[:8]]
    best_k = int(sc.order[0])
    second = float(sc.rms[sc.order[1]]) if len(sc.order) > 1 else np.inf
    ratio = second / max(float(sc.rms[best_k]), 1e-12)
    fit = "poor" if sc.rms[best_k] > POOR_RESIDUAL_DEG else ("clear" if ratio >= CLEAR_SEPARATION else "ambiguous")
    warning = _template_warning(fit_rmse, fit_rmse_limit, rows, n)
    if warning:
        fit = "poor"
    best = ranking[0]["builtins"][0] if ranking[0]["builtins"] else "custom"
    rep = {
        "mode": "landmarks",
        "source": source,
        "roles": list(roles),
        "units": "degrees",
        "samples": n,
        "candidates": len(candidates()),
        "template_offset_fitted": bool(fit_offset),
        "fit": fit,
        "best": best,
        "separation": ratio,
        "rms_residual_deg": float(sc.rms[best_k]),
        "median_residual_deg": float(sc.med[best_k]),
        "matched": ranking[0],
        "ranking": ranking,
        "hypotheses": sc.hypotheses(),
        "per_face": _per_face(rows, len(ok), row_ids, sc.res[best_k], fit_rmse),
        "rows_skipped": int((~ok).sum()),
    }
    if warning:
        rep["warning"] = warning
    c = candidates()[int(sc.lead[best_k])]
    system = (
        builtin_systems()[best]
        if best != "custom"
        else c.system(name or "custom", f"inferred from {source}: {c.formula()} (canonical frame, active)", order=roles)
    )
    rep["definition"] = system.describe()
    rep["system"] = system.to_dict()
    rep["_system"] = system
    return rep


class _Scores:
    """The residuals of the candidates worth scoring on every face: the 10 best on a subsample, and every
    built-in's reading of the labels (as the canonical map, and its stored matrix read as active)."""

    def __init__(self, pyr, R_obs, fit_offset: bool, seed: int):
        n = len(pyr)
        sub = np.arange(n) if n <= SEARCH_ROWS else np.sort(np.random.default_rng(seed).choice(n, SEARCH_ROWS, False))
        res, _ = _landmark_residuals(candidate_matrices(pyr[sub]), R_obs[sub], fit_offset)
        self.canon = builtin_canonical_by_candidate()
        self.stored = builtin_names_by_candidate()
        self.lead = np.unique(np.concatenate([np.argsort(_rms(res))[:10], list(self.canon), list(self.stored)]))
        self.res, self.Q = _landmark_residuals(candidate_matrices(pyr, self.lead), R_obs, fit_offset)
        self.rms, self.med = _rms(self.res), np.median(self.res, axis=1)
        self.order = np.argsort(self.rms, kind="stable")

    def entry(self, k, roles) -> dict:
        """The ranking entry of the ``k``-th scored candidate."""
        ci = int(self.lead[k])
        c = candidates()[ci]
        Q = self.Q[k]
        off = float(np.rad2deg(2 * np.arctan2(np.linalg.norm(Q - np.eye(3)), np.linalg.norm(Q + np.eye(3)))))
        return {
            "formula": c.formula(),
            "turns": c.words(),
            "builtins": rank_builtins(self.canon.get(ci, []), order=tuple(roles)),
            "stored_matrix_of": self.stored.get(ci, []),
            "rms_residual_deg": float(self.rms[k]),
            "median_residual_deg": float(self.med[k]),
            "max_residual_deg": float(self.res[k].max()),
            "template_offset_deg": off,
        }

    def hypotheses(self) -> list:
        """Every built-in reading of the labels (one of the candidates already scored), best first."""
        readings: dict = {}
        for ci, names in self.canon.items():
            readings.setdefault(ci, []).extend(names)
        for ci, names in self.stored.items():
            readings.setdefault(ci, []).extend(
                f"{n} (stored matrix read as active)" for n in names if n not in self.canon.get(ci, [])
            )
        pos = {int(ci): k for k, ci in enumerate(self.lead)}
        return sorted(
            (
                {
                    "readings": r,
                    "formula": candidates()[ci].formula(),
                    "rms_residual_deg": float(self.rms[pos[ci]]),
                    "median_residual_deg": float(self.med[pos[ci]]),
                    "max_residual_deg": float(self.res[pos[ci]].max()),
                }
                for ci, r in readings.items()
            ),
            key=lambda h: h["rms_residual_deg"],
        )


def _template_warning(fit_rmse, fit_rmse_limit, rows, n) -> str | None:
    """Why the verdict is ``poor`` whatever the residuals: the template fits the landmarks poorly (else None)."""
    if fit_rmse is None or fit_rmse_limit is None:
        return None
    fr = float(np.nanmedian(np.asarray(fit_rmse, dtype=np.float64)[rows])) if n else np.nan
    if fr <= fit_rmse_limit:
        return None
    return (
        f"the template fits the landmarks poorly (median RMSE {fr:.2f}, expected at most "
        f"{fit_rmse_limit:g}): check the landmark frame"
    )


def _per_face(rows, n_rows, row_ids, residuals, fit_rmse) -> list:
    """The winner's residual per face (``rows``: the input rows scored, of ``n_rows``)."""
    ids = list(range(n_rows)) if row_ids is None else list(row_ids)
    return [
        {
            "row": int(i),
            "id": ids[i],
            "residual_deg": float(v),
            **({"fit_rmse": float(fit_rmse[i])} if fit_rmse is not None else {}),
        }
        for i, v in zip(rows, residuals)
    ]
