"""The relabelling core shared by Panoptic and AGORA (SPEC §6, §7): pure numpy.

From 3-D face landmarks to labels, in three vectorised steps:

1. :func:`fit_faces`: fit WHENet's reference head to each face's confident
   landmark pairs (one batched similarity fit), and gate on pair count and
   fit residual.
2. :func:`label_matrices`: the corrected label of a face seen by a camera,
   ``A = E @ cam_R @ R_head`` (the 300W-LP matrix, SPEC §6 step 4).
3. :func:`relabel_views`: for every (face, camera) view, the label in any
   rotation system, the helmet box, the projected 2-D landmarks, WHENet's
   legacy chain if asked for, and the reason when a view is rejected.
"""

from __future__ import annotations

import numpy as np

from ...geometry.helmet import helmet_boxes
from ...geometry.line_of_sight import camera_to_crop_labels
from ...geometry.projection import project_points
from ...geometry.reference import confidence_min, helmet_preset, min_pairs, reference_head
from ...geometry.similarity import fit_similarity
from ...io import BBOX_COLS, conversion_columns, landmark_cols
from ...rotation import canonical_to_labels
from ...rotation.systems import canonical_system

#: camera frame (OpenCV: x right, y down, z forward) -> canonical 300W-LP frame (y up, z to the camera)
E = np.diag([1.0, -1.0, -1.0])

#: default fit-quality gate, world units (cm on Panoptic). On the 160906_pizza1
#: sample, the 54 fits with a consistent landmark set have RMSE 0.57-1.31 cm
#: (median 0.78); the three above 2 cm have a broken landmark set (frame 6577
#: person 2: six pairs at score 0, eye line 98 deg from the label; frame 3476
#: person 4: nose points 15 cm off; frame 6328 person 2: eye line 11 deg off).
DEFAULT_MAX_RMSE = 2.0

#: the 300W-LP system: WHENet's legacy angles are 300W-LP angles
W300LP = canonical_system()

#: views per block when projecting landmarks
VIEW_BLOCK = 256

#: a landmark coordinate beyond this (world units) is not a face
ABSURD_COORD = 1e6

REASONS = (
    "bad landmarks",
    "too few confident points",
    "bad fit",
    "behind camera",
    "outside image",
    "box rejected",
    "dropped by legacy rule",
)


def label_matrices(R_head, cam_R) -> np.ndarray:
    """Corrected 300W-LP label matrices ``A = E @ cam_R @ R_head``.

    Parameters
    ----------
    R_head : array_like, shape (N, 3, 3)
        Reference head -> world rotation of each face.
    cam_R : array_like, shape (3, 3) or (N, 3, 3)
        World -> camera rotation (OpenCV camera frame).

    Returns
    -------
    ndarray, shape (N, 3, 3)
        The face as the camera sees it, in the canonical frame (x: image
        right, y: up, z: towards the camera); a proper rotation.
    """
    return E @ np.asarray(cam_R, dtype=np.float64) @ np.asarray(R_head, dtype=np.float64)


def legacy_whenet_labels(R_head, cam_R):
    """WHENet's own label chain, exactly as ``prepare_images.py`` computes it.

    ``compound = cam_R @ R_head @ E``; its Z-Y-X decomposition
    (``inverse_rotate_zyx``: both solutions, gimbal branch when
    ``|compound[0, 2]| > 0.9999999``); ``select_euler`` (yaw above 180 wrapped,
    the first solution with ``|pitch| < 90`` and ``|roll| < 90``, else drop);
    then ``yaw = -yaw`` and ``roll = -roll``.

    Parameters
    ----------
    R_head : array_like, shape (N, 3, 3)
    cam_R : array_like, shape (3, 3) or (N, 3, 3)

    Returns
    -------
    pyr : ndarray, shape (N, 3)
        ``(pitch, yaw, roll)`` in degrees; NaN where dropped.
    kept : ndarray of bool, shape (N,)
        False where WHENet drops the row (its ``status`` is False).

    Notes
    -----
    On every kept row the result is one of the two 300W-LP triples of
    :func:`label_matrices` (the one ``select_euler`` wants), because
    ``E @ compound @ E = A`` and conjugating by ``E = Rx(180)`` negates yaw and
    roll. The intermediate ``compound`` read as a 300W-LP rotation is wrong.
    """
    M = np.asarray(cam_R, dtype=np.float64) @ np.asarray(R_head, dtype=np.float64) @ E
    m02 = M[..., 0, 2]
    lock = np.abs(m02) > 0.9999999
    with np.errstate(divide="ignore", invalid="ignore"):
        y0 = np.arcsin(np.clip(-m02, -1.0, 1.0))
        y1 = np.pi - y0
        c0, c1 = np.cos(y0), np.cos(y1)
        x0 = np.arctan2(M[..., 1, 2] / c0, M[..., 2, 2] / c0)
        x1 = np.arctan2(M[..., 1, 2] / c1, M[..., 2, 2] / c1)
        z0 = np.arctan2(M[..., 0, 1] / c0, M[..., 0, 0] / c0)
        z1 = np.arctan2(M[..., 0, 1] / c1, M[..., 0, 0] / c1)
    # gimbal branch: z = 0, y = -/+ 90, x from the first column; both sets equal
    pos = m02 > 0
    xl = np.where(pos, np.arctan2(-M[..., 1, 0], -M[..., 2, 0]), np.arctan2(M[..., 1, 0], M[..., 2, 0]))
    yl = np.where(pos, -np.pi / 2, np.pi / 2)
    s1 = np.rad2deg(np.stack([np.where(lock, xl, x0), np.where(lock, yl, y0), np.where(lock, 0.0, z0)], -1))
    s2 = np.rad2deg(np.stack([np.where(lock, xl, x1), np.where(lock, yl, y1), np.where(lock, 0.0, z1)], -1))
    for s in (s1, s2):
        s[..., 1] = np.where(s[..., 1] > 180.0, s[..., 1] - 360.0, s[..., 1])
    ok1 = (np.abs(s1[..., 2]) < 90) & (np.abs(s1[..., 0]) < 90)
    ok2 = (np.abs(s2[..., 2]) < 90) & (np.abs(s2[..., 0]) < 90)
    pyr = np.where(ok1[..., None], s1, np.where(ok2[..., None], s2, np.nan))
    pyr[..., 1] = -pyr[..., 1]
    pyr[..., 2] = -pyr[..., 2]
    return pyr, ok1 | ok2


def fit_faces(
    points,
    confidence=None,
    pairs=None,
    *,
    conf_min: float | None = None,
    min_pair_count: int | None = None,
    max_rmse: float | None = DEFAULT_MAX_RMSE,
) -> dict:
    """Fit WHENet's reference head to many faces and gate the fits.

    Parameters
    ----------
    points : array_like, shape (N, L, 3)
        3-D landmarks in world units (NaN marks a missing point).
    confidence : array_like, shape (N, L), optional
        Per-landmark confidence; a pair is used when ``> conf_min``.
    pairs : (array of int, array of int)
        (landmark indices, reference-head indices). Required.
    conf_min : float, default 0.1 (WHENet)
    min_pair_count : int, default 7 (WHENet)
    max_rmse : float or None
        Reject fits whose RMSE (world units) is above this; None or inf
        disables the gate (WHENet's behaviour).

    Returns
    -------
    dict
        The :func:`~hpe_cli.geometry.similarity.fit_similarity` keys
        (``scale, R, t, rmse, n_pairs``), plus ``ok`` (N,) bool,
        ``reason`` (N,) object (``''``, ``"bad landmarks"`` (a coordinate
        is infinite or beyond :data:`ABSURD_COORD`), ``"too few confident
        points"`` or ``"bad fit"``) and ``detail`` (N,) object.
    """
    if pairs is None:
        raise ValueError("expected pairs=(landmark indices, reference-head indices)")
    src_idx, head_idx = (np.asarray(p, dtype=np.intp) for p in pairs)
    conf_min = confidence_min() if conf_min is None else float(conf_min)
    min_pair_count = min_pairs() if min_pair_count is None else int(min_pair_count)
    points = np.asarray(points, dtype=np.float64)
    n = points.shape[0]
    # NaN marks a missing point; inf or absurd values mark a broken face (rejected, not fitted)
    with np.errstate(invalid="ignore"):
        broken = ~(np.isnan(points) | (np.abs(points) <= ABSURD_COORD)).all(axis=(1, 2))
    if broken.any():
        points = np.where(broken[:, None, None], np.nan, points)
    dst = points[:, src_idx]
    mask = np.isfinite(dst).all(-1)
    if confidence is not None:
        with np.errstate(invalid="ignore"):
            mask &= np.asarray(confidence, dtype=np.float64)[:, src_idx] > conf_min
    src = np.broadcast_to(reference_head()[head_idx], dst.shape)
    count = mask.sum(1)
    enough = count >= min_pair_count
    fit = fit_similarity(src, dst, mask & enough[:, None])
    fit["n_pairs"] = count.astype(np.int64)
    reason = np.full(n, "", dtype=object)
    detail = np.full(n, "", dtype=object)
    fitted = np.isfinite(fit["rmse"])
    if max_rmse is not None and np.isfinite(max_rmse):
        bad = fitted & (fit["rmse"] > max_rmse)
        reason[bad] = "bad fit"
        detail[bad] = [f"rmse {r:.3g} > {max_rmse:g}" for r in fit["rmse"][bad]]
    few = (~enough | ~fitted) & ~broken
    reason[few] = "too few confident points"
    detail[few] = [f"{c} of {len(src_idx)} pairs usable, need {max(min_pair_count, 3)}" for c in count[few]]
    reason[broken] = "bad landmarks"
    detail[broken] = f"a landmark coordinate is infinite or beyond {ABSURD_COORD:g}"
    fit["ok"] = reason == ""
    fit["reason"] = reason
    fit["detail"] = detail
    return fit


def relabel_views(
    fit: dict, face, cam: dict, system, *, preset="whenet", legacy: bool = False, landmarks=None, frame: str = "camera"
) -> dict:
    """Labels, boxes and 2-D landmarks of (face, camera) views.

    Parameters
    ----------
    fit : dict
        :func:`fit_faces` output for N faces.
    face : array_like of int, shape (V,)
        The face (row of ``fit``) each view shows.
    cam : dict
        Per-view camera arrays: ``K`` (V, 3, 3), ``dist`` (V, 5), ``R`` (V, 3, 3),
        ``t`` (V, 3), ``width`` (V,), ``height`` (V,).
    system : str or RotationSystem
        Target rotation system of the labels.
    preset : {"whenet", "directmhp"}
        Helmet radius and box rule.
    legacy : bool
        Label with WHENet's chain (:func:`legacy_whenet_labels`) and drop
        what it drops; otherwise the corrected formula.
    landmarks : array_like, shape (N, L, 3), optional
        3-D landmarks to project into each view.
    frame : {"camera", "crop"}
        ``camera``: labels relative to the camera's optical axis (SPEC §6);
        ``crop``: relative to the ray through the helmet centre (SPEC §10,
        :mod:`hpe_cli.geometry.line_of_sight`), with ``ray_angle`` returned.

    Returns
    -------
    dict
        ``ok`` (V,) bool; ``reason``, ``detail`` (V,) object; ``A`` (V, 3, 3)
        canonical label matrices; ``conversion`` (a
        :class:`~hpe_cli.rotation.Conversion` of the ok views, in ``system``);
        ``bbox`` (V, 4); ``legacy_pyr`` (V, 3) (legacy only, NaN where
        dropped); ``lm2d`` (V, L, 2) when ``landmarks`` is given.
    """
    face = np.asarray(face, dtype=np.intp)
    Rh = fit["R"][face]
    box = helmet_boxes(
        fit["scale"][face],
        Rh,
        fit["t"][face],
        cam["K"],
        cam["dist"],
        cam["R"],
        cam["t"],
        cam["width"],
        cam["height"],
        preset=preset,
    )
    reason = fit["reason"][face].copy()
    detail = fit["detail"][face].copy()
    face_ok = reason == ""
    take = face_ok & ~box["ok"]
    reason[take] = box["reason"][take]
    detail[take] = box["detail"][take]
    A = label_matrices(Rh, cam["R"])
    out = {"bbox": box["bbox"], "A": A}
    if frame == "crop":
        A, out["ray_angle"] = _crop_labels(A, fit, face, cam, preset)
        out["A"] = A
    elif frame != "camera":
        raise ValueError(f"expected frame 'camera' or 'crop', got {frame!r}")
    if legacy:
        cam_R = cam["R"]
        if frame == "crop":  # WHENet's chain applied to the crop camera's rotation Q.T @ cam_R
            cam_R = E @ A @ np.swapaxes(Rh, -1, -2)
        pyr, kept = legacy_whenet_labels(Rh, cam_R)
        drop = (reason == "") & ~kept & np.isfinite(A).all((1, 2))
        reason[drop] = "dropped by legacy rule"
        detail[drop] = "no triple with |pitch| < 90 and |roll| < 90"
        out["legacy_pyr"] = pyr
    ok = reason == ""
    if legacy:
        # the label is rebuilt from WHENet's own angles (equal to A to ~1e-13)
        A_ok = W300LP.from_angles(out["legacy_pyr"][ok])
    else:
        A_ok = A[ok]
    out["conversion"] = canonical_to_labels(A_ok, system)
    if landmarks is not None:
        out["lm2d"] = project_views(landmarks, face, cam)
    out.update(ok=ok, reason=reason, detail=detail)
    return out


def _crop_labels(A, fit: dict, face, cam: dict, preset: str):
    """``--frame crop``: the labels ``A`` relative to the ray through each view's helmet centre, and the ray's
    angle to the optical axis (:func:`hpe_cli.geometry.line_of_sight.camera_to_crop_labels`)."""
    off = np.asarray(helmet_preset(preset).offset, dtype=np.float64)
    world = fit["scale"][face, None] * (fit["R"][face] @ off) + fit["t"][face]
    centre = np.einsum("nij,nj->ni", np.broadcast_to(cam["R"], (len(face), 3, 3)), world) + np.broadcast_to(
        np.asarray(cam["t"], dtype=np.float64).reshape(-1, 3), (len(face), 3)
    )
    return camera_to_crop_labels(A, centre)


def project_views(landmarks, face, cam: dict) -> np.ndarray:
    """The 3-D ``landmarks`` (N, L, 3) of each view's face projected by its camera: (V, L, 2) pixels, NaN
    behind the camera (``face`` and ``cam`` as in :func:`relabel_views`)."""
    landmarks = np.asarray(landmarks, dtype=np.float64)
    uv = np.empty((len(face), landmarks.shape[1], 2))
    # blocks of views keep the temporaries small enough to stay in cache
    for s in range(0, len(face), VIEW_BLOCK):
        sl = slice(s, s + VIEW_BLOCK)
        b_uv, z = project_points(
            landmarks[face[sl]], cam["K"][sl, None], cam["dist"][sl, None], cam["R"][sl, None], cam["t"][sl, None]
        )
        b_uv[z <= 0] = np.nan
        uv[sl] = b_uv
    return uv


LEGACY_COLS = ["legacy_pitch", "legacy_yaw", "legacy_roll"]


def view_label_columns(views: dict, fit: dict, fit_index, legacy: bool) -> dict:
    """The label columns of the kept views, in the relabel output layout.

    ``views`` is :func:`relabel_views`' result, ``fit`` the fits, and
    ``fit_index`` the index into ``fit`` of each kept view's face. Returns
    ``bbox_*``, the conversion columns, ``fit_rmse, n_pairs, scale``, the
    legacy angles when ``legacy``, and ``lm{i}_x, lm{i}_y`` when ``views``
    holds projected landmarks.
    """
    ok = views["ok"]
    bbox = views["bbox"][ok]
    cols = {col: bbox[:, k] for k, col in enumerate(BBOX_COLS)}
    cols.update(conversion_columns(views["conversion"]))
    for key, col in (("rmse", "fit_rmse"), ("n_pairs", "n_pairs"), ("scale", "scale")):
        cols[col] = fit[key][fit_index]
    if legacy:
        for k, col in enumerate(LEGACY_COLS):
            cols[col] = views["legacy_pyr"][ok, k]
    if "ray_angle" in views:
        cols["ray_angle"] = views["ray_angle"][ok]
    if "lm2d" in views:
        # one contiguous row per output column (strided columns cost a copy each in Arrow)
        lm2d = views["lm2d"][ok]
        lm = np.ascontiguousarray(lm2d.reshape(len(lm2d), lm2d.shape[1] * 2).T)
        for k, col in enumerate(landmark_cols(lm.shape[0] // 2)):
            cols[col] = lm[k]
    return cols


def summary_tail(
    legacy: bool, dropped: int, considered: int, out_of_range: int, gimbal: int, sysname: str, unit: str, dropper: str
) -> list:
    """The closing summary lines shared by the relabel pipelines (legacy share, range, lock)."""
    lines = []
    if legacy:
        share = 100.0 * dropped / considered if considered else 0.0
        lines.append(f"WHENet's legacy rule dropped {dropped} of {considered} {unit} ({share:.1f}%)")
    if out_of_range:
        lines.append(
            f"{out_of_range} labels lie outside {sysname}'s declared range "
            f"(for whenet: no triple with |pitch| < 90 and |roll| < 90; {dropper} would drop them)"
        )
    if gimbal:
        lines.append(f"{gimbal} labels are within the gimbal-lock tolerance (see gimbal_lock)")
    return lines
