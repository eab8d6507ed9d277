"""300W-LP / AFLW2000-3D ``.mat`` files (MATLAB v5, SPEC §8).

``Pose_Para`` is 1x7: pitch, yaw, roll (radians, 300W-LP system), tdx, tdy,
tdz, scale. ``pt2d`` is 2x68 (300W-LP) or 2x21 (AFLW2000, -1 marks an invisible
point, returned here as NaN). ``pt3d_68`` is 3x68: image x, image y, depth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError
from .mat_fields import check_fields

POSE_COLS = ["pitch", "yaw", "roll", "tdx", "tdy", "tdz", "scale"]


def read_mat(path, fileobj=None) -> dict:
    """Read one ``.mat`` label file (or ``fileobj``, e.g. a zip member in a BytesIO, named ``path`` in errors).

    Returns
    -------
    dict
        ``pose`` (7,) float64 with angles converted to **degrees**,
        ``pt2d`` (2, N) with NaN for invisible points (or None),
        ``pt3d_68`` (3, 68) (or None).
    """
    import scipy.io

    path = Path(path)
    try:
        m = scipy.io.loadmat(fileobj if fileobj is not None else path, variable_names=["Pose_Para", "pt2d", "pt3d_68"])
    except Exception as exc:  # scipy raises many types for truncated/corrupt files
        raise HpeError(f"{path}: not a readable MATLAB .mat file ({' '.join(str(exc).split())[:160]})") from None

    m = check_fields(m, path)  # field types checked at the door (cell arrays, structs, char arrays)
    if "Pose_Para" not in m:
        if fileobj is not None:
            fileobj.seek(0)
        keys = scipy.io.whosmat(fileobj if fileobj is not None else path)
        raise HpeError(f"{path}: no Pose_Para variable (keys: {', '.join(k[0] for k in keys)})")
    pose = np.asarray(m["Pose_Para"], dtype=np.float64).reshape(-1)
    if pose.size < 3:
        raise HpeError(f"{path}: Pose_Para has {pose.size} values, expected 7")
    pose = np.concatenate([pose, np.full(max(0, 7 - pose.size), np.nan)])[:7]
    pose[:3] = np.rad2deg(pose[:3])
    pt2d = m.get("pt2d")
    if pt2d is not None:
        pt2d = np.asarray(pt2d, dtype=np.float64)
        if pt2d.ndim != 2 or pt2d.shape[0] != 2:
            raise HpeError(f"{path}: pt2d has shape {pt2d.shape}, expected (2, N)")
        # AFLW2000-3D marks an invisible point with x = -1; its y is then a filler
        # (452 in PRNet's copies, 2 px below a 450-px image), not -1
        pt2d = np.where((pt2d[0] == -1) | (pt2d[1] == -1), np.nan, pt2d)
    pt3d = m.get("pt3d_68")
    if pt3d is not None:
        pt3d = np.asarray(pt3d, dtype=np.float64)
        if pt3d.shape != (3, 68):
            raise HpeError(f"{path}: pt3d_68 has shape {pt3d.shape}, expected (3, 68)")
    return {"pose": pose, "pt2d": pt2d, "pt3d_68": pt3d}


def mat_files(path) -> list:
    path = Path(path)
    files = [path] if path.is_file() else sorted(path.glob("*.mat"))
    if not files:
        raise HpeError(f"{path}: no .mat files found")
    return files


def read_mat_dir(path, landmarks: bool = False):
    """All ``.mat`` files of a folder (or one file) as a label table.

    Columns: ``file`` (name relative to the folder), ``image`` (the image the
    file labels: the same name with ``.jpg``, as AFLW2000-3D and 300W-LP ship
    them; the key ``hpe evaluate`` joins on), ``pitch, yaw, roll``
    (degrees, 300W-LP system), ``tdx, tdy, tdz, scale``; with ``landmarks``
    also ``lm{i}_x, lm{i}_y`` from ``pt2d`` (NaN = invisible) and
    ``lm3d{i}_x, lm3d{i}_y, lm3d{i}_z`` from ``pt3d_68`` when every file has it.
    """
    import pandas as pd

    path = Path(path)
    files = mat_files(path)
    recs = [read_mat(f) for f in files]
    base = path if path.is_dir() else path.parent
    frame = pd.DataFrame(np.stack([r["pose"] for r in recs]), columns=POSE_COLS)
    rel = [f.relative_to(base) for f in files]
    frame.insert(0, "file", [str(r) for r in rel])
    frame.insert(1, "image", [r.with_suffix(".jpg").as_posix() for r in rel])
    frame.attrs["system"] = "300w_lp"  # Pose_Para is always 300W-LP's convention
    frame.attrs["one_record_files"] = True  # a bad row is named by its .mat file
    if not landmarks:
        return frame
    extra = {}
    n2 = {r["pt2d"].shape[1] for r in recs if r["pt2d"] is not None}
    if len(n2) == 1 and all(r["pt2d"] is not None for r in recs):
        pts = np.stack([r["pt2d"] for r in recs])  # (N, 2, L)
        for i in range(pts.shape[2]):
            extra[f"lm{i}_x"], extra[f"lm{i}_y"] = pts[:, 0, i], pts[:, 1, i]
    if all(r["pt3d_68"] is not None for r in recs):
        p3 = np.stack([r["pt3d_68"] for r in recs])
        for i in range(68):
            for n, a in enumerate("xyz"):
                extra[f"lm3d{i}_{a}"] = p3[:, n, i]
    out = pd.concat([frame, pd.DataFrame(extra)], axis=1)
    out.attrs.update(frame.attrs)
    return out
