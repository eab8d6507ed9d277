"""Score predictions against ground truth: core metrics, protocols, alignment, breakdowns (pure numpy).

:func:`evaluate` is the array API (``hpe_cli.evaluate``, whole arrays in memory). ``hpe evaluate``
(:mod:`hpe_cli.pipelines.evaluate`) reads and pairs tables chunk by chunk, scores each chunk with
:func:`compute_rows` and sums the results with :class:`hpe_cli.metrics.stream.Accumulator`; both give the same
report blocks (tested in ``tests/evaluate/test_evaluate_streaming.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotation import soa
from ..rotation.check import rotation_reasons
from ..rotation.systems import get_system
from . import rotation_errors as re_
from .align import mean_offset, remove_offset
from .protocols import PROTOCOLS, PosePair, summarize

#: thresholds (degrees) of the ``within_*`` fractions of the geodesic error
WITHIN = (5, 10, 15, 30)
ANGLES = ("pitch", "yaw", "roll")


@dataclass
class PairRows:
    """Per-row results for the valid pairs (all arrays have N rows)."""

    geodesic: np.ndarray
    maev: np.ndarray
    frobenius: np.ndarray
    mae_wrapped: np.ndarray
    mae_best_of_two: np.ndarray
    gt_angles: np.ndarray
    pred_angles: np.ndarray
    protocols: dict
    #: what ``compute_rows(..., hook=f)`` returned of ``f(pair)`` (None without a hook)
    extra: object = None

    @property
    def n(self) -> int:
        return len(self.geodesic)


def check_protocols(protocols) -> list:
    """Protocol names (all when None), each checked; raises ``ValueError`` naming the valid ones."""
    if protocols is None:
        return list(PROTOCOLS)
    if isinstance(protocols, str):
        protocols = [protocols]
    names = list(dict.fromkeys(protocols))
    bad = [p for p in names if p not in PROTOCOLS]
    if bad:
        raise ValueError(f"unknown protocol {bad[0]!r}; expected one of: {', '.join(PROTOCOLS)}")
    return names


def compute_rows(P, G, gt_system, protocols=None, raw=None, context=None, hook=None) -> PairRows:
    """Every per-row error for canonical rotations ``P`` (predicted) and ``G`` (true).

    ``raw`` (``{"pred" | "gt": (system, angles (N, 3))}``) holds the angles as
    written for sides given as angles (see :class:`PosePair`). ``hook(pair)``, when given, runs on the same
    :class:`PosePair` after the protocols (sharing their cached decompositions); its result is ``extra``.
    """
    pair = PosePair(P, G, gt_system, raw, context)
    pair.core_errors()  # geodesic, maev and Frobenius in one compiled pass where it gives their bits
    g = pair.primary(gt_system, "gt")  # hpe's own metrics: primary solutions (of the matrices)
    p1, p2 = pair.angles(gt_system, "pred")
    best, _, wrapped = re_.best_and_wrapped(p1, p2, g)
    protos = {name: PROTOCOLS[name].func(pair) for name in check_protocols(protocols)}
    return PairRows(
        pair.geodesic(),
        pair.maev(),
        pair.frobenius(),
        wrapped,
        best,
        g,
        p1,
        protos,
        None if hook is None else hook(pair),
    )


def _f(x) -> float | None:
    return float(x) if np.size(x) else None


def _angle_means(e) -> dict:
    means = [_f(e[:, k].mean()) if len(e) else None for k in range(3)]
    out = dict(zip(ANGLES, means))
    out["mean"] = float(np.mean(means)) if len(e) else None
    return out


def metrics_summary(rows: PairRows, subset=None) -> dict:
    """The ``metrics`` block of the report over ``subset`` (boolean mask; all rows when None)."""
    sel = (lambda a: a) if subset is None else (lambda a: a[subset])
    geo = sel(rows.geodesic)
    n = len(geo)
    if n:
        q = np.percentile(geo, [50, 90, 95])
        geodesic = {
            "mean": float(geo.mean()),
            "median": float(q[0]),
            "p90": float(q[1]),
            "p95": float(q[2]),
            "max": float(geo.max()),
        }
        geodesic.update({f"within_{t}": float((geo <= t).mean()) for t in WITHIN})
    else:
        geodesic = {k: None for k in ("mean", "median", "p90", "p95", "max")}
        geodesic.update({f"within_{t}": None for t in WITHIN})
    mv = sel(rows.maev)
    maev = {a: (float(mv[:, k].mean()) if n else None) for k, a in enumerate(re_.AXES)}
    maev["mean"] = float(mv.mean()) if n else None
    fro = sel(rows.frobenius)
    return {
        "geodesic": geodesic,
        "maev": maev,
        "frobenius": {"mean": float(fro.mean()) if n else None},
        "mae_wrapped": _angle_means(sel(rows.mae_wrapped)),
        "mae_best_of_two": _angle_means(sel(rows.mae_best_of_two)),
    }


def summary(rows: PairRows, subset=None) -> dict:
    """``{"n", "metrics", "protocols"}`` over ``subset``."""
    n = rows.n if subset is None else int(np.count_nonzero(subset))
    return {
        "n": n,
        "metrics": metrics_summary(rows, subset),
        "protocols": {name: summarize(pr, subset, name) for name, pr in rows.protocols.items()},
    }


def yaw_bin_edges(gt_system, width: float) -> np.ndarray:
    """Bin edges of ``width`` degrees over the GT system's whole yaw range."""
    lo, hi = gt_system.ranges.get("yaw", (-180.0, 180.0))
    n = max(1, int(np.ceil((hi - lo) / width - 1e-9)))
    return np.minimum(lo + width * np.arange(n + 1), hi)


def _groups(values):
    """``(codes, labels)`` of a column of group values (any dtype, NaN as its own group)."""
    import pandas as pd

    codes, uniques = pd.factorize(pd.Series(values), use_na_sentinel=False, sort=True)
    return codes, [(_plain(u)) for u in uniques]


def _plain(u):
    if isinstance(u, np.generic):
        u = u.item()
    if isinstance(u, float) and np.isnan(u):
        return "NaN"
    return u if isinstance(u, (str, int, float, bool)) or u is None else str(u)


def evaluate_canonical(
    P,
    G,
    *,
    gt_system,
    protocols=None,
    align: str = "none",
    by=None,
    by_name: str = "by",
    yaw_bins: float | None = None,
    raw=None,
):
    """Score canonical rotations ``P`` against ``G``; return ``(report_part, rows)``.

    ``report_part`` holds ``metrics``, ``protocols``, ``align`` and, when
    asked, ``by`` and ``yaw_bins``; ``rows`` is the :class:`PairRows` after
    alignment (for per-row output and plots).
    """

    gt_system = get_system(gt_system)
    protocols = check_protocols(protocols)
    out = {}
    P = re_.as_nested(P)
    G = re_.as_nested(G)
    if align not in ("none", "mean"):
        raise ValueError(f"expected align 'none' or 'mean', got {align!r}")
    if align == "mean":
        before = compute_rows(P, G, gt_system, protocols, raw)
        Q = mean_offset(P, G)
        Qg = gt_system.from_canonical(Q[None])
        qp, _, _, _ = gt_system.to_angles(Qg)
        angle = float(re_.geodesic_deg(Q[None], np.eye(3)[None])[0])
        P = remove_offset(P, Q)
        raw = {k: v for k, v in (raw or {}).items() if k != "pred"}  # the aligned predictions have no written angles
        out["align"] = {
            "method": "mean",
            "offset_deg": angle,
            "offset_angles": dict(zip(ANGLES, map(float, qp[0]))),
            "offset_matrix_canonical": Q.tolist(),
            "gt_system": gt_system.name,
            "before": {
                "metrics": metrics_summary(before),
                "protocols": {k: summarize(v, None, k) for k, v in before.protocols.items()},
            },
        }
    else:
        out["align"] = {"method": "none"}
    rows = compute_rows(P, G, gt_system, protocols, raw)
    s = summary(rows)
    out["metrics"] = s["metrics"]
    out["protocols"] = s["protocols"]
    if by is not None:
        codes, labels = _groups(by)
        out["by"] = {"column": by_name, "groups": {str(lab): summary(rows, codes == k) for k, lab in enumerate(labels)}}
    if yaw_bins:
        edges = yaw_bin_edges(gt_system, float(yaw_bins))
        y = rows.gt_angles[:, 1]
        idx = np.clip(np.searchsorted(edges, y, side="right") - 1, 0, len(edges) - 2)
        out["yaw_bins"] = [
            {"lo": float(edges[k]), "hi": float(edges[k + 1]), **summary(rows, idx == k)} for k in range(len(edges) - 1)
        ]
    return out, rows


def _to_canonical(values, system, columns, side):
    """``(canonical nested list, invalid mask, reasons)`` from angles (N, 3) or matrices (N, 3, 3)."""

    a = np.asarray(values, dtype=np.float64)
    if columns is None:
        columns = "matrix" if a.ndim == 3 or (a.ndim == 2 and a.shape[-1] == 9) else "angles"
    if columns == "angles":
        if a.ndim != 2 or a.shape[1] != 3:
            raise ValueError(f"{side}: expected angles of shape (N, 3), got {a.shape}")
        bad = ~np.isfinite(a).all(axis=1)
        reasons = np.where(bad, "non-finite angle", "").astype(object)
        a = np.where(bad[:, None], 0.0, a)
        X = system.soa_to_canonical(system.soa_from_angles(a[:, 0], a[:, 1], a[:, 2]))
        return soa.from_array(soa.to_array(X, len(a))), bad, reasons
    if columns == "matrix":
        a = a.reshape(-1, 3, 3) if a.ndim == 2 and a.shape[-1] == 9 else a
        if a.ndim != 3 or a.shape[1:] != (3, 3):
            raise ValueError(f"{side}: expected matrices of shape (N, 3, 3), got {a.shape}")
        reasons = rotation_reasons(a)
        bad = reasons != ""
        a = np.where(bad[:, None, None], np.eye(3), a)
        X = system.soa_to_canonical(soa.from_array(a))
        return soa.from_array(soa.to_array(X, len(a))), bad, reasons
    raise ValueError(f"expected columns None, 'angles' or 'matrix', got {columns!r}")


def evaluate(pred, gt, *, pred_system, gt_system, protocols=None, align: str = "none", columns=None) -> dict:
    """Score predicted head poses against ground truth, each in its own rotation system.

    Parameters
    ----------
    pred, gt : array_like
        ``(N, 3)`` angles (pitch, yaw, roll; degrees) or ``(N, 3, 3)`` stored
        matrices of ``pred_system`` / ``gt_system``. Row ``i`` of ``pred`` is
        scored against row ``i`` of ``gt``.
    pred_system, gt_system : str or RotationSystem
        A built-in name (see ``hpe systems``), a ``.toml`` path or a system.
    protocols : list of str, optional
        Protocol names (see :data:`hpe_cli.metrics.protocols.PROTOCOLS`); all when None.
    align : {"none", "mean"}
        ``"mean"`` removes the constant rotation offset (see :mod:`hpe_cli.metrics.align`).
    columns : {None, "angles", "matrix"} or tuple of two
        What the arrays hold (per side when a tuple); None infers it from the shape.

    Returns
    -------
    dict
        ``{"n": {"gt", "pred", "pairs", "missing", "invalid"}, "systems",
        "metrics", "protocols", "align"}``, angles in degrees; the same
        report as ``hpe evaluate --json``. Non-finite or non-rotation rows
        are counted in ``invalid`` and left out of every metric.

    Raises
    ------
    ValueError
        Mismatched row counts, bad shapes, unknown protocol or system.
    """

    ps, gs = get_system(pred_system), get_system(gt_system)
    cp, cg = columns if isinstance(columns, (tuple, list)) else (columns, columns)
    P, bad_p, _ = _to_canonical(pred, ps, cp, "pred")
    G, bad_g, _ = _to_canonical(gt, gs, cg, "gt")
    n_p, n_g = len(bad_p), len(bad_g)
    if n_p != n_g:
        raise ValueError(f"expected as many predictions as ground-truth rows, got {n_p} and {n_g}")
    ok = ~(bad_p | bad_g)
    if not ok.all():
        P = [[x[ok] for x in r] for r in P]
        G = [[x[ok] for x in r] for r in G]
    raw = {}
    for side, vals, sysm in (("pred", pred, ps), ("gt", gt, gs)):
        a = np.asarray(vals, dtype=np.float64)
        if a.ndim == 2 and a.shape[1] == 3 and (cp if side == "pred" else cg) in (None, "angles"):
            raw[side] = (sysm, a[ok])  # angles as written: the raw-angle protocols compare these
    part, _ = evaluate_canonical(P, G, gt_system=gs, protocols=protocols, align=align, raw=raw)
    report = {
        "n": {"gt": n_g, "pred": n_p, "pairs": int(ok.sum()), "missing": 0, "invalid": int((~ok).sum())},
        "systems": {"pred": ps.name, "gt": gs.name},
    }
    report.update(part)
    return report
