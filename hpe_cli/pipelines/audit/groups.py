"""The views and time checks of ``hpe audit --consistency`` (:mod:`hpe_cli.pipelines.audit.consistency`).

Both need groups of rows (one head at one frame; one track over frames), so they
run once all rows are read, on the label matrices and keys the audit held for
tables with a ``frame`` column (about 100 bytes per row). Each returns the
per-row angle (float64), a reason code per row (uint8, an index into the texts
:func:`view_texts` / :func:`time_texts` give) and its JSON summary.
"""

from __future__ import annotations

import numpy as np

from ...metrics import consistency as mc
from .common import _stats

#: views of one head at one frame needed for a consensus
MIN_VIEWS = 3


def view_texts(default: str) -> tuple:
    """Reason texts of the views check by code; code 0 is ``default`` (the check's set-up reason, or "")."""
    return (
        default,
        "camera not in the calibration",
        "label not finite",
        f"fewer than {MIN_VIEWS} views of this head at this frame",
    )


def time_texts(has_frame: bool, max_gap: int) -> tuple:
    """Reason texts of the time check by code."""
    return (
        "" if has_frame else "no frame column",
        f"no neighbour on both sides within {max_gap} frames",
        "label not finite",
    )


def camera_rotations(cons, cams, seqs) -> np.ndarray:
    """(n, 3, 3) rotation of each row's camera (its calibration of the row's sequence when calibrations are per
    sequence), NaN where none is known; ``cams``/``seqs`` are the coded camera and sequence columns."""
    cam_names = {v: k for k, v in cons.code_tables["camera"].items()}
    seq_names = {v: k for k, v in cons.code_tables["sequence"].items()}
    cam_R = np.full((len(cams), 3, 3), np.nan)
    for c in np.unique(cams):  # one per camera (and sequence), not per row
        sel = cams == c
        name = cam_names.get(int(c))
        if None in cons.cams:
            cam = cons.cams[None].get(name)
            if cam is not None:
                cam_R[sel] = cam[0]
        else:
            for sc in np.unique(seqs[sel]):
                cam = cons.cams.get(seq_names.get(int(sc)), {}).get(name)
                if cam is not None:
                    cam_R[sel & (seqs == sc)] = cam[0]
    return cam_R


def view_groups(keys, usable, code):
    """The ``usable`` rows sorted into groups of one head at one time (``keys``: the view columns, then the
    frame): ``(order, starts)``. Rows of groups with fewer than :data:`MIN_VIEWS` views get code 3 in ``code``
    (changed in place) and are left out."""
    idx = np.flatnonzero(usable)
    order = idx[np.lexsort([k[idx] for k in reversed(keys)])]
    kmat = np.stack([k[order] for k in keys], 1)
    starts = mc.group_starts(kmat)
    sizes = np.diff(np.append(starts, len(order)))
    big = np.repeat(sizes >= MIN_VIEWS, sizes)
    code[order[~big]] = 3
    return order[big], mc.group_starts(kmat[big])


def views(cons, P, finite):
    """``(angle, code, summary)`` of the views check (:func:`hpe_cli.metrics.consistency.view_consensus`)."""
    N = len(P["frame"])
    angle = np.full(N, np.nan)
    code = np.zeros(N, dtype=np.uint8)
    if cons.view_reason:
        return angle, code, {"checked": 0, "reason": cons.view_reason}
    cams = P["camera"]
    cam_names = {v: k for k, v in cons.code_tables["camera"].items()}
    cam_R = camera_rotations(cons, cams, P.get("sequence"))
    have_cam = np.isfinite(cam_R).all((1, 2))
    code[~have_cam] = 1
    code[~finite] = 2
    order, starts = view_groups([P[c] for c in cons.view_cols] + [P["frame"]], have_cam & finite, code)
    res = mc.view_consensus(P["A"][order], cam_R[order], starts)
    angle[order] = res["angle"]
    cams_out, named = [], []
    if len(order):
        off = mc.camera_offsets(res["offset"], cams[order])
        for k in np.argsort(-off["angle"]):
            entry = {
                "camera": cam_names.get(int(off["codes"][k])),
                "rows": int(off["n"][k]),
                "offset_deg": round(float(off["angle"][k]), 4),
                "rotvec_deg": [round(float(v), 4) for v in off["median"][k]],
                "significant": bool(off["significant"][k]),
            }
            cams_out.append(entry)
            if entry["significant"]:
                named.append(entry["camera"])
    ok = np.isfinite(angle)
    summary = {
        "calibration": cons.calibration_files,
        "checked": int(ok.sum()),
        "groups": int(len(starts)),
        "min_views": MIN_VIEWS,
        "angle_deg": _stats(angle[ok]),
        "cameras_with_offset": named,
        "cameras": cams_out,
    }
    return angle, code, summary


def time_rates(cons, P, finite):
    """``(rate, code)`` of every row of ``P``: its turn rate (deg/frame) against its track's neighbouring frames
    (:func:`hpe_cli.metrics.consistency.temporal_jumps`), and the reason code of the rows without one (1: no
    neighbour within ``max_gap``, 2: no finite label). Shared by the whole-table and the streamed checks."""
    N = len(P["frame"])
    keys = [P[c] for c in cons.track_cols] + [P["frame"]]
    idx = np.flatnonzero(finite)
    order = idx[np.lexsort([k[idx] for k in reversed(keys)])]
    tracks = np.stack([k[order] for k in keys[:-1]], 1) if cons.track_cols else np.zeros((len(order), 1))
    starts = mc.group_starts(tracks)
    res = mc.temporal_jumps(P["A"][order], P["frame"][order], starts, cons.s.max_gap)
    rate = np.full(N, np.nan)
    rate[order] = res["rate"]
    code = np.zeros(N, dtype=np.uint8)
    code[~np.isfinite(rate)] = 1
    code[~finite] = 2
    return rate, code


def time_check(cons, P, finite):
    """``(rate, code, summary)`` of the time check (:func:`time_rates` and its summary)."""
    rate, code = time_rates(cons, P, finite)
    ok = np.isfinite(rate)
    flagged = ok & (rate > cons.s.max_jump_deg)
    summary = {
        "tracks": [*cons.track_cols] or ["(whole table)"],
        "checked": int(ok.sum()),
        "jumps": int(flagged.sum()),
        "rate_deg_per_frame": _stats(rate[ok]),
    }
    return rate, code, summary
