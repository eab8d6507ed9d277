"""``hpe evaluate``: the rows set aside (missing, invalid, unmatched, unreadable) and the alignment block of the report."""

from __future__ import annotations

import numpy as np

from ...metrics import rotation_errors as re_
from .join import row_reasons, where
from .sides import Chunk

ANGLES = ("pitch", "yaw", "roll")


def add_rejects(rej, side, name, rows, reasons, keycols):
    """Rejected rows of ``side`` (its own file and line), the first one named in the error message."""
    if not len(rows):
        return
    unit = side.unit
    if rej.first_where is None:
        rej.first_where = f"{where(side, rows[0])}: {reasons[0]}".replace(f"{side.path}: ", "", 0)
        rej.source = side.path
    rej.add(
        {
            **keycols,
            "side": np.full(len(rows), name, dtype=object),
            "input": np.full(len(rows), str(side.path), dtype=object),
            unit: side.lines[rows],
        },
        np.asarray(reasons, dtype=object),
    )


def collect_rejects(rej, gt, pred, gidx, pidx, unmatched, key_cols):
    """Send unreadable, missing, invalid and unmatched rows to ``rej``; return the masks over GT rows."""
    missing = pidx < 0
    p_ok = np.where(missing, False, pred.ok[np.maximum(pidx, 0)])
    valid = ~missing & gt.ok[gidx] & p_ok
    invalid = ~missing & ~valid
    for side, name in ((gt, "gt"), (pred, "pred")):
        unreadable_rejects(rej, side, name)
    rows = gidx[missing]
    add_rejects(
        rej,
        gt,
        "gt",
        rows,
        np.full(len(rows), "missing: no prediction for this ground-truth row", dtype=object),
        key_cols(gt, rows),
    )
    rows, prow = gidx[invalid], pidx[invalid]
    gt_bad = ~gt.ok[rows]
    add_rejects(
        rej,
        gt,
        "gt",
        rows[gt_bad],
        ("invalid: gt " + row_reasons(gt, rows[gt_bad])).astype(object),
        key_cols(gt, rows[gt_bad]),
    )
    add_rejects(
        rej,
        pred,
        "pred",
        prow[~gt_bad],
        ("invalid: prediction " + row_reasons(pred, prow[~gt_bad])).astype(object),
        key_cols(pred, prow[~gt_bad]),
    )
    add_rejects(
        rej,
        pred,
        "pred",
        unmatched,
        np.full(len(unmatched), "unmatched: prediction with no ground-truth row", dtype=object),
        key_cols(pred, unmatched),
    )
    return valid, missing, invalid


def stream_rejects(rej, s, g: Chunk, p: Chunk, bad):
    gt_bad = bad & ~g.ok
    pred_bad = bad & g.ok & ~p.ok

    def keycols(c, m):
        if s.keys:
            return {k: c.keys.column(k).filter(m).to_numpy(zero_copy_only=False) for k in s.keys}
        return {}

    for c, m, name, side, what in ((g, gt_bad, "gt", s.gside, "gt"), (p, pred_bad, "pred", s.pside, "prediction")):
        if m.any():
            rs = c.reasons[m] if c.reasons is not None else np.full(int(m.sum()), "not usable", dtype=object)
            reasons = ("invalid: " + what + " " + rs.astype(str)).astype(object)
            unit = side.unit
            lines = c.lines[m]
            if rej.first_where is None:
                rej.first_where, rej.source = f"{unit} {int(lines[0])}: {reasons[0]}", side.path
            rej.add(
                {
                    **keycols(c, m),
                    "side": np.full(len(lines), name, dtype=object),
                    "input": np.full(len(lines), str(side.path), dtype=object),
                    unit: lines,
                },
                reasons,
            )


def unreadable_rejects(rej, side, name):
    """Send ``side``'s unreadable rows (``name``: "gt" or "pred") to ``rej``, each with its line and reason."""
    if side.unreadable:
        ln = np.array([u[0] for u in side.unreadable], dtype=np.int64)
        if rej.first_where is None:
            rej.first_where, rej.source = f"line {ln[0]}: unreadable {name} row: {side.unreadable[0][1]}", side.path
        rej.add(
            {
                "side": np.full(len(ln), name, dtype=object),
                "input": np.full(len(ln), str(side.path), dtype=object),
                "line": ln,
            },
            np.array([f"unreadable {name} row: {u[1]}" for u in side.unreadable], dtype=object),
            lines=ln,
        )


def align_block(glob, rep_before, gsys) -> dict:

    Q = glob["Q"]
    qp, _, _, _ = gsys.to_angles(gsys.from_canonical(Q[None]))
    return {
        "method": "mean",
        "offset_deg": float(re_.geodesic_deg(Q[None], np.eye(3)[None])[0]),
        "offset_angles": dict(zip(ANGLES, map(float, qp[0]))),
        "offset_matrix_canonical": Q.tolist(),
        "gt_system": gsys.name,
        "estimate": "hpe chordal mean over all pairs (not opal23's Karcher mean)",
        "before": {"metrics": rep_before["metrics"], "protocols": rep_before["protocols"]},
    }
