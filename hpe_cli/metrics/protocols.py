"""Published head-pose evaluation protocols, each reproduced from its code (pure numpy).

Each protocol takes a :class:`PosePair` (predicted and true rotations as
canonical 300W-LP matrices), converts both sides to its own system *through
the matrices*, applies its own filter, and returns per-row errors
(:class:`ProtocolRows`). Summaries over any subset of rows (all rows, a
``--by`` group, a yaw bin) are made by :func:`summarize`.

The source file each protocol reproduces is named in its docstring and in
:data:`PROTOCOLS`. Where a published computation is ill-defined, it is still
computed exactly as published and the problem is stated in ``notes``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import rotation_errors as re_

_DEG = 180.0 / np.pi


class PosePair:
    """Predicted (``P``) and true (``G``) canonical rotations with cached conversions.

    Parameters
    ----------
    P, G : nested list (3x3 of 1-D arrays) or ndarray (N, 3, 3)
        Canonical 300W-LP matrices (``A = Rx(p).T Ry(y).T Rz(r).T``).
    gt_system : RotationSystem
        The ground truth's own system (used by the core metrics and opal23).
    """

    def __init__(self, P, G, gt_system):
        self.P = re_.as_nested(P)
        self.G = re_.as_nested(G)
        self.gt_system = gt_system
        self.n = int(np.broadcast(*[x for row in self.G for x in row]).shape[0])
        self._cache = {}

    def stored(self, system, side: str):
        """Nested stored matrix of ``side`` ('pred' or 'gt') in ``system``."""
        from ..rotation.systems import get_system

        system = get_system(system)
        key = ("stored", system.name, side)
        if key not in self._cache:
            self._cache[key] = system.soa_from_canonical(self.P if side == "pred" else self.G)
        return self._cache[key]

    def angles(self, system, side: str):
        """``(primary, secondary)`` angles ``(N, 3)`` (pitch, yaw, roll; degrees) of ``side`` in ``system``."""
        from ..rotation.systems import get_system

        system = get_system(system)
        key = ("angles", system.name, side)
        if key not in self._cache:
            p1, p2, _, _ = system.soa_to_angles(self.stored(system, side))
            self._cache[key] = (np.stack(np.broadcast_arrays(*p1), -1), np.stack(np.broadcast_arrays(*p2), -1))
        return self._cache[key]

    def array(self, system, side: str) -> np.ndarray:
        """Stored matrices of ``side`` in ``system`` as ``(N, 3, 3)``."""
        X = self.stored(system, side)
        out = np.empty((self.n, 3, 3))
        for i in range(3):
            for j in range(3):
                out[:, i, j] = X[i][j]
        return out


@dataclass
class ProtocolRows:
    """Per-row result of one protocol.

    Attributes
    ----------
    err : ndarray (N, 3)
        Per-angle errors in the order (pitch, yaw, roll), degrees.
    keep : ndarray of bool (N,)
        Rows the protocol's filter keeps.
    splits : dict
        name -> boolean mask (N,): extra summaries of ``err`` over ``keep & mask``.
    scalars : dict
        name -> per-row values (N,): reported as their mean over ``keep``.
    vectors : dict
        name -> (labels, per-row values (N, k)): per-column means over ``keep``
        plus their mean.
    """

    err: np.ndarray
    keep: np.ndarray
    splits: dict = field(default_factory=dict)
    scalars: dict = field(default_factory=dict)
    vectors: dict = field(default_factory=dict)
    angle_labels: tuple = ("pitch", "yaw", "roll")


@dataclass(frozen=True)
class Protocol:
    name: str
    system: str
    formula: str
    filter: str
    source: str
    func: Callable
    notes: tuple = ()


def _within_99(pyr) -> np.ndarray:
    """All three |angles| <= 99 degrees (FSA-Net, 6DRepNet and img2pose test filters)."""
    return (np.abs(pyr) <= 99.0).all(axis=-1)


def _sixdrepnet_euler(R) -> np.ndarray:
    """6DRepNet's ``compute_euler_angles_from_rotation_matrices`` on stored 6drepnet matrices.

    ``sy = sqrt(R00^2 + R10^2)``; regular rows: ``x = atan2(R21, R22)``,
    ``y = atan2(-R20, sy)``, ``z = atan2(R10, R00)``; rows with ``sy < 1e-6``:
    ``x = atan2(-R12, R11)``, ``z = 0``. Returned as (pitch, yaw, roll) =
    (x, y, z) in degrees (sixdrepnet/utils.py).
    """
    sy = np.sqrt(R[0][0] * R[0][0] + R[1][0] * R[1][0])
    singular = sy < 1e-6
    x = np.where(singular, np.arctan2(-R[1][2], R[1][1]), np.arctan2(R[2][1], R[2][2]))
    y = np.arctan2(-R[2][0], sy)
    z = np.where(singular, 0.0, np.arctan2(R[1][0], R[0][0]))
    return np.stack(np.broadcast_arrays(x, y, z), -1) * _DEG


def _sixdrepnet_min(pred, gt) -> np.ndarray:
    """min(|gt - p|, |p + 360 - gt|, |p - 360 - gt|, |p + 180 - gt|, |p - 180 - gt|) per angle."""
    # min(|d + c|, |d - c|) = ||d| - c| exactly (c >= 0), so three terms give the five
    a = np.abs(pred - gt)
    out = np.abs(a - 180.0)
    np.minimum(out, a, out=out)
    np.minimum(out, np.abs(a - 360.0), out=out)
    return out


# ---------------------------------------------------------------------------- protocols
def hopenet(pair: PosePair) -> ProtocolRows:
    """Hopenet: plain |pred - gt| per angle in the ``300w_lp`` system, no wrap, no filter.

    Reproduces ``code/test_hopenet.py`` (natanielruiz/deep-head-pose):
    ``yaw_error += sum(abs(yaw_predicted - label_yaw))`` and the same for
    pitch and roll, divided by the number of images.
    """
    p, _ = pair.angles("300w_lp", "pred")
    g, _ = pair.angles("300w_lp", "gt")
    return ProtocolRows(re_.abs_error(p, g), np.ones(pair.n, dtype=bool))


def fsanet(pair: PosePair) -> ProtocolRows:
    """FSA-Net: as hopenet, keeping GT rows whose three angles are all within [-99, 99].

    Reproduces ``training_and_testing/FSANET_test.py`` (shamangary/FSA-Net):
    ``if np.max(temp_pose) <= 99.0 and np.min(temp_pose) >= -99.0`` on the GT
    (yaw, pitch, roll), then ``np.mean(np.abs(p_data - y_data), axis=0)``.
    """
    p, _ = pair.angles("300w_lp", "pred")
    g, _ = pair.angles("300w_lp", "gt")
    return ProtocolRows(re_.abs_error(p, g), _within_99(g))


def sixdrepnet(pair: PosePair) -> ProtocolRows:
    """6DRepNet: min over d, d +- 360, d +- 180 per angle in the ``6drepnet`` system, GT within +-99.

    Reproduces ``sixdrepnet/test.py`` (thohemp/6DRepNet): Euler angles from
    ``utils.compute_euler_angles_from_rotation_matrices`` and
    ``min(|gt - p|, |p + 360 - gt|, |p - 360 - gt|, |p + 180 - gt|, |p - 180 - gt|)``;
    the +-99 filter is ``sixdrepnet/create_filename_list.py`` (the test list
    keeps files with all three |Pose_Para| <= 99 degrees).
    """
    p = _sixdrepnet_euler(pair.stored("6drepnet", "pred"))
    g = _sixdrepnet_euler(pair.stored("6drepnet", "gt"))
    return ProtocolRows(_sixdrepnet_min(p, g), _within_99(g))


def sixdrepnet360(pair: PosePair) -> ProtocolRows:
    """6DRepNet360: the same five-term minimum as 6DRepNet, no filter, plus VMAE.

    Reproduces ``sixdrepnet360/test.py`` (thohemp/6DRepNet360): the per-angle
    error is the same ``min`` over d, d +- 360, d +- 180 as 6DRepNet (the
    published code keeps the +-180 terms), and ``Vec1..Vec3`` are
    ``acos(clamp(sum(R_gt[:, k] * R_pred[:, k])))``: the angle between row
    ``k`` of the stored 6drepnet matrices, i.e. column ``k`` of the canonical
    ones (``vmae``: left, down, front and their mean).
    """
    p = _sixdrepnet_euler(pair.stored("6drepnet", "pred"))
    g = _sixdrepnet_euler(pair.stored("6drepnet", "gt"))
    return ProtocolRows(_sixdrepnet_min(p, g), np.ones(pair.n, dtype=bool),
                        vectors={"vmae": (re_.AXES, re_.maev_deg(pair.P, pair.G))})


def directmhp(pair: PosePair) -> ProtocolRows:
    """DirectMHP: |d| per angle in the ``whenet`` system with only yaw wrapped; front/back split.

    Reproduces ``mean_absolute_error_calculate`` in ``utils/mae.py``
    (hnuzhy/DirectMHP): ``error_list = abs(gt - pd)``,
    ``error_list[:, 1] = min(error_list[:, 1], 360 - error_list[:, 1])``;
    ``back`` rows have ``abs(gt_yaw) > 90``, the others are ``front``.
    """
    p, _ = pair.angles("whenet", "pred")
    g, _ = pair.angles("whenet", "gt")
    e = re_.abs_error(p, g)
    e[:, 1] = np.minimum(e[:, 1], 360.0 - e[:, 1])
    back = np.abs(g[:, 1]) > 90.0
    return ProtocolRows(e, np.ones(pair.n, dtype=bool), splits={"front": ~back, "back": back})


def whenet(pair: PosePair) -> ProtocolRows:
    """WHENet: every angle wrapped, min(e, 360 - e), in the ``whenet`` system; also |GT yaw| <= 90.

    WHENet's repository (Ascend-Research/HeadPoseEstimation-WHENet) publishes
    no evaluation script; this is the paper's "wrapped MAE", as quoted in the
    ``compute_mae`` docstring of opal23's ``test/evaluator.py``
    ("min(MAE, 360 - MAE)"), with WHENet's full-range labels (``select_euler``).
    ``narrow`` is the summary over rows with |GT yaw| <= 90.
    """
    p, _ = pair.angles("whenet", "pred")
    g, _ = pair.angles("whenet", "gt")
    return ProtocolRows(re_.wrapped_error(p, g), np.ones(pair.n, dtype=bool),
                        splits={"narrow": np.abs(g[:, 1]) <= 90.0})


def opal23(pair: PosePair) -> ProtocolRows:
    """opal23: the better of the prediction's two Euler solutions, wrapped, plus geodesic error.

    Reproduces ``Evaluator.compute_mae`` and ``compute_ge`` in ``test/evaluator.py``
    (pcr-upm/opal23_headpose), in the GT system: raw errors of both
    solutions compared by their mean, the smaller kept, each wrapped
    ``min(e, 360 - e)``; ``geodesic`` = ``arccos((trace(G P^T) - 1) / 2)``.
    """
    g, _ = pair.angles(pair.gt_system, "gt")
    p1, p2 = pair.angles(pair.gt_system, "pred")
    e, second = re_.best_of_two_error(p1, p2, g)
    return ProtocolRows(e, np.ones(pair.n, dtype=bool),
                        scalars={"geodesic": re_.geodesic_deg(pair.P, pair.G),
                                 "second_solution_fraction": second.astype(np.float64)})


def headposeplus(pair: PosePair) -> ProtocolRows:
    """HeadPose+: plain |d| in two formats, ``pyr`` (``biwi`` system) and ``ypr`` (``300w_lp``).

    Reproduces ``hpp/calc_error.py`` (kuhnkeF/headposeplus): ``pyr`` is SciPy
    ``as_euler('xyz')`` of the rotation, ``ypr`` Hopenet/FSA-Net's reading
    (``_ypr2pyr`` / ``_pyr2ypr``); errors ``mean(abs(arr - gt_arr), axis=0)``.
    The top-level pitch/yaw/roll are the ``pyr`` errors; ``ypr`` is an extra.
    HeadPose+ applies ``as_euler('xyz')`` to the 300W-LP matrix itself, whose
    yaw and roll are the ``biwi`` system's with both signs flipped on both
    sides; absolute differences are the same.
    """
    p, _ = pair.angles("biwi", "pred")
    g, _ = pair.angles("biwi", "gt")
    py, _ = pair.angles("300w_lp", "pred")
    gy, _ = pair.angles("300w_lp", "gt")
    return ProtocolRows(re_.abs_error(p, g), np.ones(pair.n, dtype=bool),
                        vectors={"ypr": (("pitch", "yaw", "roll"), re_.abs_error(py, gy))})


def img2pose(pair: PosePair) -> ProtocolRows:
    """img2pose: mean |d| of rotation-vector components (OpenCV camera frame), GT within +-99.

    Reproduces ``evaluation/jupyter_notebooks/aflw_2000_3d_evaluation.ipynb``
    (vitoralbiero/img2pose): ``pose_mae = mean(abs(predictions - targets))``
    on the 6-DoF vectors whose first three entries are the rotation vector
    (``cv2.Rodrigues`` of the ``opencv`` matrix), times 180/pi, printed as
    "Pitch" (x), "Yaw" (y), "Roll" (z); images with any |Pose_Para| > 99
    degrees are skipped. The numbers are rotation-vector components, not
    Euler angles: the report labels them ``rotvec_x/y/z``.
    """
    rp = re_.rotvec_deg(pair.stored("opencv", "pred"))
    rg = re_.rotvec_deg(pair.stored("opencv", "gt"))
    g300, _ = pair.angles("300w_lp", "gt")
    return ProtocolRows(re_.abs_error(rp, rg), _within_99(g300), angle_labels=("rotvec_x", "rotvec_y", "rotvec_z"))


def dad3dheads(pair: PosePair) -> ProtocolRows:
    """DAD-3DHeads: mean ||I - R_pred R_gt^T||_F (no angles).

    Reproduces ``DADEvaluator.pose_error`` in ``dad_3dheads_benchmark/benchmark.py``
    (PinataFarms/DAD-3DHeads): ``np.linalg.norm(np.eye(3) - R_pred @ R_gt.T, "fro")``.
    The norm is the same in every frame, so no system is needed; pitch, yaw
    and roll are reported as null.
    """
    nan = np.full((pair.n, 3), np.nan)
    return ProtocolRows(nan, np.ones(pair.n, dtype=bool), scalars={"frobenius": re_.frobenius(pair.P, pair.G)})


_FLIPS = "the +-180 terms forgive a prediction whose angle is off by 180 degrees, so flipped answers are hidden"
_BRANCH = "plain |d| of Euler angles compares solution branches: a correct rotation stated with the other " \
          "solution (or past the system's range) scores a large error"

PROTOCOLS = {p.name: p for p in (
    Protocol("hopenet", "300w_lp", "|d| per angle, no wrap", "none",
             "natanielruiz/deep-head-pose code/test_hopenet.py", hopenet, (_BRANCH,)),
    Protocol("fsanet", "300w_lp", "|d| per angle, no wrap", "GT |pitch|,|yaw|,|roll| <= 99",
             "shamangary/FSA-Net training_and_testing/FSANET_test.py", fsanet, (_BRANCH,)),
    Protocol("6drepnet", "6drepnet", "min(|d|, |d+-360|, |d+-180|) per angle", "GT |pitch|,|yaw|,|roll| <= 99",
             "thohemp/6DRepNet sixdrepnet/test.py (+ create_filename_list.py)", sixdrepnet, (_FLIPS,)),
    Protocol("6drepnet360", "6drepnet", "min(|d|, |d+-360|, |d+-180|) per angle; vmae = column angles",
             "none", "thohemp/6DRepNet360 sixdrepnet360/test.py", sixdrepnet360, (_FLIPS,)),
    Protocol("directmhp", "whenet", "|d|, yaw wrapped min(e, 360-e); front |GT yaw|<=90 / back", "none",
             "hnuzhy/DirectMHP utils/mae.py", directmhp,
             ("pitch and roll are not wrapped: " + _BRANCH,)),
    Protocol("whenet", "whenet", "min(e, 360-e) per angle; narrow |GT yaw|<=90", "none",
             "WHENet paper (no evaluation script published); opal23 test/evaluator.py quotes it", whenet, ()),
    Protocol("opal23", "gt", "better of the two Euler solutions, wrapped; geodesic", "none",
             "pcr-upm/opal23_headpose test/evaluator.py", opal23, ()),
    Protocol("headposeplus", "biwi + 300w_lp", "|d| per angle in pyr (biwi) and ypr (300w_lp)", "none",
             "kuhnkeF/headposeplus hpp/calc_error.py", headposeplus, (_BRANCH,)),
    Protocol("img2pose", "opencv rotvec", "|d| of rotation-vector components (not Euler angles)",
             "GT |pitch|,|yaw|,|roll| <= 99",
             "vitoralbiero/img2pose evaluation/jupyter_notebooks/aflw_2000_3d_evaluation.ipynb", img2pose,
             ("rotation-vector components are printed as pitch/yaw/roll by img2pose; they are not Euler angles",)),
    Protocol("dad3dheads", "any", "||I - P G^T||_F", "none",
             "PinataFarms/DAD-3DHeads dad_3dheads_benchmark/benchmark.py", dad3dheads, ()),
)}


def protocol_names() -> list:
    return list(PROTOCOLS)


def _mean(x) -> float | None:
    x = np.asarray(x, dtype=np.float64)
    return float(x.mean()) if x.size and not np.isnan(x).all() else None


def _angles_summary(err, mask, labels) -> dict:
    e = err if mask.all() else err[mask]
    out = {"n": int(mask.sum())}
    means = [_mean(e[:, k]) for k in range(3)]
    out.update(dict(zip(labels, means)))
    out["mean"] = float(np.mean(means)) if all(m is not None for m in means) else None
    return out


def summarize(rows: ProtocolRows, subset=None, name: str = "") -> dict:
    """Report dict of one protocol over ``subset`` (a boolean mask; all rows when None)."""
    n = len(rows.keep)
    subset = np.ones(n, dtype=bool) if subset is None else subset
    mask = subset & rows.keep
    out = _angles_summary(rows.err, mask, rows.angle_labels)
    out["dropped"] = int((subset & ~rows.keep).sum())
    if rows.angle_labels != ("pitch", "yaw", "roll"):
        out.update({"pitch": out[rows.angle_labels[0]], "yaw": out[rows.angle_labels[1]],
                    "roll": out[rows.angle_labels[2]]})
    for k, m in rows.splits.items():
        out[k] = _angles_summary(rows.err, mask & m, rows.angle_labels)
    for k, v in rows.scalars.items():
        out[k] = _mean(v[mask])
    for k, (labels, v) in rows.vectors.items():
        means = [_mean(v[mask][:, j]) for j in range(v.shape[1])]
        d = dict(zip(labels, means))
        d["mean"] = float(np.mean(means)) if means and all(m is not None for m in means) else None
        out[k] = d
    if out["mean"] is None and "frobenius" in rows.scalars:
        out["mean"] = out["frobenius"]
    p = PROTOCOLS.get(name)
    if p is not None:
        out["system"] = p.system
        out["source"] = p.source
        if p.notes:
            out["notes"] = list(p.notes)
    return out
