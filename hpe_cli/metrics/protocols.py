"""Published head-pose evaluation protocols, each reproduced from its peer's current code.

Each protocol takes a :class:`PosePair` (predicted and true rotations as
canonical 300W-LP matrices, plus the angles as written for sides given as
angles) and reads what its peer's code reads: raw-angle protocols (hopenet,
fsanet, headposeplus, directmhp, whenet and the GT side of 6drepnet,
6drepnet360 and img2pose) compare the angles as written whenever they mean the
same rotation in the protocol's system, and count the rows they had to
re-express (``re_expressed``); matrix-reading protocols decode the matrix the
way the peer does. Summaries over any subset of rows (all rows, a ``--by``
group, a yaw bin) are made by :func:`summarize`.

Every protocol's ``source`` names ``repo@commit file:lines`` of the code it
reproduces (see :data:`PROTOCOLS`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..registry import Registry
from . import peer_angles as pa_
from . import rotation_errors as re_
from .pose_pair import PosePair


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
    reexpressed : dict
        side -> boolean mask (N,) of rows given as angles whose numbers the
        protocol had to convert into its own system (see :meth:`PosePair.written`),
        or None when that side came as matrices/vectors.
    counts : dict
        name -> boolean mask (N,): reported as the number of kept rows in it.
    """

    err: np.ndarray
    keep: np.ndarray
    splits: dict = field(default_factory=dict)
    scalars: dict = field(default_factory=dict)
    vectors: dict = field(default_factory=dict)
    angle_labels: tuple = ("pitch", "yaw", "roll")
    reexpressed: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Protocol:
    name: str
    system: str
    formula: str
    filter: str
    source: str
    func: Callable
    notes: tuple = ()
    units: str = "deg"


#: name -> :class:`Protocol`, in the order reports list them (``hpe evaluate --protocol NAME``)
PROTOCOLS = Registry("protocol")


def register_protocol(
    name: str, system: str, formula: str, filter: str, source: str, *, notes: tuple = (), units: str = "deg"
) -> Callable:
    """Decorator: register ``func(pair: PosePair) -> ProtocolRows`` as the protocol ``name`` in :data:`PROTOCOLS`.

    Parameters
    ----------
    name : str
        ``hpe evaluate --protocol NAME``.
    system : str
        The system whose angles the peer's code reads (words, for the report).
    formula, filter : str
        The error formula and the rows the peer keeps, in words (the report and ``--help``).
    source : str
        ``repo@commit file:lines`` of the peer code reproduced.
    notes : tuple of str
        Caveats printed with the protocol's numbers.
    units : {"deg", "unitless"}
        Unit of the errors.
    """

    def add(func: Callable) -> Callable:
        PROTOCOLS.register(name, Protocol(name, system, formula, filter, source, func, tuple(notes), units))
        return func

    return add


def _within_99(pyr) -> np.ndarray:
    """All three |angles| <= 99 degrees (FSA-Net, 6DRepNet and img2pose test filters); NaN is outside.

    Column by column: numpy's ``all(axis=-1)`` over three booleans a row is 8x slower."""
    a = np.abs(pyr)
    keep = a[:, 0] <= 99.0
    keep &= a[:, 1] <= 99.0
    keep &= a[:, 2] <= 99.0
    return keep


def _written_pair(pair, system):
    p, cp = pair.written(system, "pred")
    g, cg = pair.written(system, "gt")
    return p, g, {"pred": cp, "gt": cg}


_FLIPS = "the +-180 terms forgive a prediction whose angle is off by 180 degrees, so flipped answers are hidden"
_BRANCH = (
    "plain |d| of Euler angles compares solution branches: a correct rotation stated with the other "
    "solution (or past the system's range) scores a large error"
)


def _written_abs_error(pair, system):
    """``|pred - gt|`` of the angles as written in ``system`` (:func:`_written_pair`), once per chunk: hopenet,
    fsanet and headposeplus's ``ypr`` block share it (read only: a protocol that changes it takes a copy)."""
    return _cached(pair, ("abs_error", system), lambda: re_.abs_error(*_written_pair(pair, system)[:2]))


# ---------------------------------------------------------------------------- protocols
@register_protocol(
    "hopenet",
    "300w_lp",
    "|d| per angle as written, no wrap",
    "none",
    "natanielruiz/deep-head-pose@f7bbb99 code/test_hopenet.py:104-106,124-127,143-145",
    notes=(_BRANCH,),
)
def hopenet(pair: PosePair) -> ProtocolRows:
    """Hopenet: plain |pred - gt| per 300w_lp angle as written, no wrap, no filter.

    natanielruiz/deep-head-pose@f7bbb99 code/test_hopenet.py:124-127:
    ``yaw_error += sum(abs(yaw_predicted - label_yaw))`` (float32 tensors).
    """
    _, _, rx = _written_pair(pair, "300w_lp")
    return ProtocolRows(_written_abs_error(pair, "300w_lp"), np.ones(pair.n, dtype=bool), reexpressed=rx)


@register_protocol(
    "fsanet",
    "300w_lp",
    "|d| per angle as written, no wrap",
    "GT |pitch|,|yaw|,|roll| <= 99",
    "shamangary/FSA-Net@4361d0e training_and_testing/FSANET_test.py:88-101,444-448",
    notes=(_BRANCH,),
)
def fsanet(pair: PosePair) -> ProtocolRows:
    """FSA-Net: as hopenet, keeping GT rows whose three written angles are all within [-99, 99].

    shamangary/FSA-Net@4361d0e training_and_testing/FSANET_test.py:88-101
    (``np.max(temp_pose) <= 99.0 and np.min(temp_pose) >= -99.0``) and 444-448
    (``np.mean(np.abs(p_data - y_data), axis=0)``).
    """
    _, g, rx = _written_pair(pair, "300w_lp")
    return ProtocolRows(_written_abs_error(pair, "300w_lp"), _within_99(g), reexpressed=rx)


def _cached(pair, key, make):
    """``make()`` once per pair: protocols that share a decomposition (6DRepNet's Euler angles, the
    axis angles, opal23's matrices) compute it once per chunk."""
    if key not in pair._cache:
        pair._cache[key] = make()
    return pair._cache[key]


def _sixd(pair, with_180: bool, filt: bool) -> ProtocolRows:
    p = _cached(pair, ("6drepnet", "euler"), lambda: pa_.sixdrepnet_euler(pair.stored("6drepnet", "pred")))
    g, cg = pair.written("6drepnet", "gt")
    keep = _within_99(g) if filt else np.ones(pair.n, dtype=bool)
    vec = {}
    if not filt:
        vec["vmae"] = (re_.AXES, _cached(pair, ("6drepnet", "vmae"), lambda: pa_.column_acos_deg(pair.P, pair.G, True)))
    err = _cached(pair, ("6drepnet", "min", with_180), lambda: pa_.min_wrapped(p, g, with_180))
    return ProtocolRows(err, keep, vectors=vec, reexpressed={"pred": None, "gt": cg})


@register_protocol(
    "6drepnet",
    "6drepnet",
    "min(|d|, |d+-360|, |d+-180|); pred Euler from its matrix",
    "GT |pitch|,|yaw|,|roll| <= 99",
    "thohemp/6DRepNet@464b2ba sixdrepnet/test.py:113-142,162-164; utils.py:165-184; create_filename_list.py:53",
    notes=(_FLIPS,),
)
def sixdrepnet(pair: PosePair) -> ProtocolRows:
    """6DRepNet: predicted matrix -> Euler, 5-term wrapped minimum against the GT label as written, GT within 99.

    thohemp/6DRepNet@464b2ba sixdrepnet/test.py:113-142 (GT ``cont_labels``,
    prediction ``compute_euler_angles_from_rotation_matrices``, ``min`` over d,
    d +- 360, d +- 180); the +-99 filter is sixdrepnet/create_filename_list.py:53.
    """
    return _sixd(pair, True, True)


@register_protocol(
    "6drepnet360",
    "6drepnet",
    "min(|d|, |d+-360|); vmae = axis angles",
    "none",
    "thohemp/6DRepNet360@b06e4fe sixdrepnet360/test.py:164-193 (3 terms since 9c1cfaf)",
)
def sixdrepnet360(pair: PosePair) -> ProtocolRows:
    """6DRepNet360 (current): the 3-term minimum over d, d +- 360, no filter, plus VMAE.

    thohemp/6DRepNet360@b06e4fe sixdrepnet360/test.py:164-193 (the +-180 terms
    were dropped in 9c1cfaf, 2024-05-29); ``Vec1..3`` = ``acos(clamp(R_gt[:, k] .
    R_pred[:, k]))`` (rows of the stored matrix = the head's axes).
    """
    return _sixd(pair, False, False)


@register_protocol(
    "6drepnet360-2023",
    "6drepnet",
    "SUPERSEDED: min(|d|, |d+-360|, |d+-180|); vmae",
    "none",
    "thohemp/6DRepNet360@5b0622d sixdrepnet360/test.py:188-193 (superseded by 9c1cfaf, 2024-05-29)",
    notes=(_FLIPS, "superseded by the 3-term minimum in 9c1cfaf; kept only to reproduce 2023 numbers"),
)
def sixdrepnet360_2023(pair: PosePair) -> ProtocolRows:
    """6DRepNet360 before 9c1cfaf (superseded): the 5-term minimum incl. d +- 180, no filter, VMAE."""
    return _sixd(pair, True, False)


def _directmhp(pair: PosePair, split: float) -> ProtocolRows:
    _, g, rx = _written_pair(pair, "whenet")

    def make():  # the errors do not depend on the split: directmhp, -v2 and -single share them
        e = _written_abs_error(pair, "whenet").copy()
        e[:, 1] = np.minimum(e[:, 1], 360.0 - e[:, 1])
        return e

    back = np.abs(g[:, 1]) > split
    e = _cached(pair, ("directmhp", "err"), make)
    return ProtocolRows(e, np.ones(pair.n, dtype=bool), splits={"front": ~back, "back": back}, reexpressed=rx)


# stacked decorators apply bottom-up: the lower one registers first
@register_protocol(
    "directmhp-v2",
    "whenet",
    "|d| as written, yaw wrapped; back |GT yaw| > 90 (v2)",
    "none",
    "hnuzhy/DirectMHP@a51b06b utils/mae.py:162-278 mean_absolute_error_calculate_v2 (CMU, AGORA)",
    notes=("pitch and roll are not wrapped: " + _BRANCH,),
)
@register_protocol(
    "directmhp",
    "whenet",
    "single or v2 by the GT dataset; v2 (|GT yaw| > 90) when it is not known",
    "none",
    "hnuzhy/DirectMHP@a51b06b utils/mae.py:162-356: directmhp-single for .mat folders, AFLW2000, "
    "300W-LP, BIWI; directmhp-v2 for CMU Panoptic, AGORA",
    notes=("pitch and roll are not wrapped: " + _BRANCH,),
)
def directmhp(pair: PosePair) -> ProtocolRows:
    """DirectMHP ``mean_absolute_error_calculate_v2`` (CMU Panoptic, AGORA): whenet labels as written.

    hnuzhy/DirectMHP@a51b06b utils/mae.py:162-278: ``abs(gt - pd)``, only yaw
    wrapped ``min(e, 360 - e)``; ``back`` rows have ``abs(gt_yaw) > 90``.
    """
    return _directmhp(pair, 90.0)


@register_protocol(
    "directmhp-single",
    "whenet",
    "|d| as written, yaw wrapped; back |GT yaw| > 99",
    "none",
    "hnuzhy/DirectMHP@a51b06b utils/mae.py:281-356 mean_absolute_error_calculate_single (AFLW2000, 300W-LP, BIWI)",
    notes=("pitch and roll are not wrapped: " + _BRANCH,),
)
def directmhp_single(pair: PosePair) -> ProtocolRows:
    """DirectMHP ``mean_absolute_error_calculate_single`` (AFLW2000, 300W-LP, BIWI): back = ``abs(gt_yaw) > 99``.

    hnuzhy/DirectMHP@a51b06b utils/mae.py:281-356 (the split at line 324).
    """
    return _directmhp(pair, 99.0)


@register_protocol(
    "whenet",
    "whenet",
    "min(e, 360-e) per angle as written; narrow |GT yaw|<=90",
    "none",
    "WHENet paper (no script published); pcr-upm/opal23_headpose@78c0c45 test/evaluator.py:56-59",
)
def whenet(pair: PosePair) -> ProtocolRows:
    """WHENet: every angle wrapped, min(e, 360 - e), whenet labels as written; also |GT yaw| <= 90.

    WHENet's repository publishes no evaluation script; this is the paper's
    "wrapped MAE", as quoted in opal23_headpose@78c0c45 test/evaluator.py:56-59.
    """
    p, g, rx = _written_pair(pair, "whenet")
    return ProtocolRows(
        re_.wrapped_error(p, g), np.ones(pair.n, dtype=bool), splits={"narrow": np.abs(g[:, 1]) <= 90.0}, reexpressed=rx
    )


def opal23_mats(pair):
    """opal23's matrices of both sides (nested) and the re-expressed rows; computed once per pair (cached), with
    the quaternions they are built from (:func:`_opal23_quats`)."""

    def make():
        p, g, rx = _written_pair(pair, "300w_lp")
        (qp, P), (qg, G) = pa_.opal23_quats_and_matrices(p), pa_.opal23_quats_and_matrices(g)
        pair._cache[("opal23", "quats")] = (qp, qg)
        return P, G, rx

    return _cached(pair, ("opal23", "mats"), make)


def _opal23_quats(pair) -> tuple:
    """The quaternions (x, y, z, w columns) of :func:`opal23_mats`'s prediction and GT matrices."""
    opal23_mats(pair)
    return pair._cache[("opal23", "quats")]


def _opal23_gt_euler(pair) -> np.ndarray:
    """``as_euler('XYZ')`` of opal23's GT matrices: shared by opal23 and opal23-align (cached)."""
    return _cached(pair, ("opal23", "gt_euler"), lambda: pa_.opal23_euler(opal23_mats(pair)[1]))


@register_protocol(
    "opal23",
    "300w_lp -> from_euler('XYZ', [p, -y, r])",
    "better of two solutions, wrapped; geodesic",
    "none",
    "pcr-upm/opal23_headpose@78c0c45 test/evaluator.py:51-93",
)
def opal23(pair: PosePair) -> ProtocolRows:
    """opal23: ``compute_mae`` and ``compute_ge`` on ``Rotation.from_euler('XYZ', [pitch, -yaw, roll])`` matrices.

    pcr-upm/opal23_headpose@78c0c45 test/evaluator.py:51-93; the matrices are
    built from the annotation angles as the images_framework AFLW2000 reader
    does, whatever the dataset (here: the 300w_lp angles as written).
    """
    P, G, rx = opal23_mats(pair)
    return ProtocolRows(
        pa_.opal23_mae(G, P, ann_euler=_opal23_gt_euler(pair)),
        np.ones(pair.n, dtype=bool),
        scalars={"geodesic": pa_.opal23_geodesic(G, P)},
        reexpressed=rx,
    )


@register_protocol(
    "opal23-align",
    "300w_lp -> from_euler('XYZ', [p, -y, r])",
    "opal23 after its Karcher-mean alignment (rows > 90 deg off left out of the mean)",
    "none",
    "pcr-upm/opal23_headpose@78c0c45 test/evaluator.py:95-129 align_predictions, then 51-93",
)
def opal23_align(pair: PosePair) -> ProtocolRows:
    """opal23 after ``Evaluator.align_predictions`` (test/evaluator.py:95-129): Karcher mean offset removed.

    The mean of ``P G^T`` is taken over the rows within 90 degrees of the
    identity only (``left_out_of_mean`` counts the others); every prediction
    is then turned by its inverse. A streamed run estimates the mean over all
    pairs first and passes it in ``pair.context["opal23_mean"]``, or scores
    the chunk's :func:`opal23_align_inputs` once the mean is known
    (:func:`opal23_align_rows`).
    """
    mean = pair.context.get("opal23_mean")
    if mean is None:
        P, G, _ = opal23_mats(pair)
        deltas, near = pa_.opal23_near_quats(G, P)
        return opal23_align_rows(opal23_align_inputs(pair, near), pa_.opal23_karcher(deltas))
    return opal23_align_rows(opal23_align_inputs(pair), mean)


#: the per-row arrays of :func:`opal23_align_inputs`, in the order a spill writes them
OPAL23_ALIGN_INPUTS = ("qP", "qG", "gt_euler", "near", "rx_pred", "rx_gt")


def opal23_align_inputs(pair: PosePair, near=None) -> dict:
    """What opal23-align reads of a chunk before the Karcher mean is known: the quaternions of opal23's rotations
    of both sides (``qP``, ``qG``: ``(4, N)``, x, y, z, w; their matrices are rebuilt from them bit for bit), the
    GT's ``as_euler('XYZ')`` (``gt_euler``), the rows within 90 degrees of the identity (``near``) and the
    re-expressed rows (``rx_pred``, ``rx_gt``: masks, or None for a side given as matrices). Arrays only, so a
    run can spill them (91 bytes a pair) and score them once its pass over every pair is over
    (:func:`opal23_align_rows`)."""
    P, G, rx = opal23_mats(pair)
    if near is None:
        near = pa_.opal23_near_mask(G, P)
    qp, qg = _opal23_quats(pair)
    return {
        "qP": np.stack(np.broadcast_arrays(*qp)),
        "qG": np.stack(np.broadcast_arrays(*qg)),
        "gt_euler": _opal23_gt_euler(pair),
        "near": near,
        "rx_pred": rx["pred"],
        "rx_gt": rx["gt"],
    }


def opal23_align_rows(inputs: dict, mean) -> ProtocolRows:
    """opal23-align's rows of one chunk's :func:`opal23_align_inputs` for the Karcher ``mean`` (3, 3)."""
    P, G = (pa_.opal23_matrix_of_quats(tuple(inputs[k])) for k in ("qP", "qG"))
    Pa, _ = pa_.opal23_align(G, P, mean=mean)
    n = len(inputs["near"])
    return ProtocolRows(
        pa_.opal23_mae(G, Pa, ann_euler=inputs["gt_euler"]),
        np.ones(n, dtype=bool),
        scalars={"geodesic": pa_.opal23_geodesic(G, Pa)},
        counts={"left_out_of_mean": ~inputs["near"]},
        reexpressed={"pred": inputs["rx_pred"], "gt": inputs["rx_gt"]},
    )


@register_protocol(
    "headposeplus",
    "300w_lp (ypr) + scipy xyz (pyr)",
    "|d| per angle in pyr and ypr",
    "none",
    "kuhnkeF/headposeplus@b94d162 hpp/calc_error.py:14-18,40-70",
    notes=(_BRANCH,),
)
def headposeplus(pair: PosePair) -> ProtocolRows:
    """HeadPose+: |d| in two blocks, ``pyr`` (SciPy ``as_euler('xyz')``) and ``ypr`` (the labels as written).

    kuhnkeF/headposeplus@b94d162 hpp/calc_error.py:14-18 (``_ypr2pyr``), 40-70
    (``calc_error``: ``mean(abs(arr - gt_arr), axis=0)`` per block). The
    top-level pitch/yaw/roll are the ``pyr`` block; ``ypr`` is an extra.
    ``as_euler('xyz')`` of the 300W-LP matrix gives the biwi angles with yaw
    and roll negated on both sides: the absolute differences are the same.
    """
    p = pair.primary("biwi", "pred")
    g = pair.primary("biwi", "gt")
    _, _, rx = _written_pair(pair, "300w_lp")
    e = re_.abs_error(p, g)
    return ProtocolRows(
        e,
        np.ones(pair.n, dtype=bool),
        vectors={
            "pyr": (("pitch", "yaw", "roll"), e),
            "ypr": (("pitch", "yaw", "roll"), _written_abs_error(pair, "300w_lp")),
        },
        reexpressed=rx,
    )


@register_protocol(
    "img2pose",
    "img2pose -> convert_to_aflw",
    "|d| of convert_to_aflw Euler angles vs Pose_Para",
    "GT |pitch|,|yaw|,|roll| <= 99",
    "vitoralbiero/img2pose@fd5473e evaluation/jupyter_notebooks/aflw_2000_3d_evaluation.ipynb"
    ":112-118,276,324 (lines of the .ipynb JSON: convert_to_aflw, the 99 skip, pose_mae)",
    notes=(_BRANCH,),
)
def img2pose(pair: PosePair) -> ProtocolRows:
    """img2pose: ``convert_to_aflw`` Euler angles of the prediction vs Pose_Para as written, GT within 99.

    vitoralbiero/img2pose@fd5473e evaluation/jupyter_notebooks/aflw_2000_3d_evaluation.ipynb
    (notebook lines 112-118 ``convert_to_aflw``, 276 the +-99 skip, 324
    ``pose_mae = mean(abs(predictions - targets))``); compared as Euler angles
    since March 2021 (rotation-vector components before).
    """
    p = pa_.img2pose_euler(pair.stored("img2pose", "pred"))
    g, cg = pair.written("300w_lp", "gt")
    return ProtocolRows(re_.abs_error(p, g), _within_99(g), reexpressed={"pred": None, "gt": cg})


@register_protocol(
    "trinet",
    "trinet",
    "min(|d|, |d+-360|, |d+-180|) of W300_R2EulerAngles; vmae",
    "none",
    "chuzcjoe/TriNet@d2689de computeMAE.py:84-89,92-197",
    notes=(_FLIPS,),
)
def trinet(pair: PosePair) -> ProtocolRows:
    """TriNet: Euler angles of the [left|down|front] matrices, 5-term minimum, and vector MAE.

    chuzcjoe/TriNet@d2689de computeMAE.py:92-197 (``W300_Get_MAE_NPY``,
    ``mode='svd'``): GT and SVD-projected prediction through
    ``W300_R2EulerAngles`` (84-89), errors as 6DRepNet's 5-term minimum, vector
    errors ``acos(clip(gt_v . pred_v))`` of the (normalised) columns.
    """
    T = pair.stored("trinet", "pred")
    Tg = pair.stored("trinet", "gt")
    e = pa_.min_wrapped(pa_.trinet_euler(T), pa_.trinet_euler(Tg), True)
    return ProtocolRows(e, np.ones(pair.n, dtype=bool), vectors={"vmae": (re_.AXES, pa_.column_acos_deg(T, Tg))})


@register_protocol(
    "opentrack",
    "trinet (XYZ of [p, -y, r])",
    "arccos(cos a cos b + sin a sin b) per angle; geodesic",
    "none",
    "opentrack/neuralnet-tracker-traincode@8d2478c trackertraincode/eval.py:337-354; utils.py:41-62",
    notes=("the peer's arccos is not clipped (NaN rows, counted in peer_nan_rows); hpe clips it to [-1, 1]",),
)
def opentrack(pair: PosePair) -> ProtocolRows:
    """opentrack: wrapped Euler errors ``arccos(cos a cos b + sin a sin b)`` and quaternion geodesic.

    opentrack/neuralnet-tracker-traincode@8d2478c trackertraincode/eval.py:337-354
    (``_angle_errors``, ``_aflw3d_euler_errors``) with utils.py:41-62; the
    peer does not clip the ``arccos`` argument, so rows where rounding puts it
    above 1 are NaN there: hpe clips it and counts them (``peer_nan_rows``).
    """
    a = pa_.opentrack_euler(pair.stored("trinet", "pred"))
    b = pa_.opentrack_euler(pair.stored("trinet", "gt"))
    e, nan = pa_.opentrack_errors(a, b)
    return ProtocolRows(
        e, np.ones(pair.n, dtype=bool), scalars={"geodesic": pair.geodesic()}, counts={"peer_nan_rows": nan}
    )


@register_protocol(
    "dad3dheads",
    "any",
    "||I - P G^T||_F (unitless)",
    "none",
    "PinataFarms/DAD-3DHeads@4fc16a2 dad_3dheads_benchmark/benchmark.py:79-83",
    units="unitless",
)
def dad3dheads(pair: PosePair) -> ProtocolRows:
    """DAD-3DHeads: mean ||I - R_pred R_gt^T||_F (unitless; no angles).

    PinataFarms/DAD-3DHeads@4fc16a2 dad_3dheads_benchmark/benchmark.py:79-83
    (``DADEvaluator.pose_error``). The norm is the same in every frame.
    """
    nan = np.full((pair.n, 3), np.nan)
    return ProtocolRows(nan, np.ones(pair.n, dtype=bool), scalars={"frobenius": pair.frobenius()})


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
        out.update(
            {"pitch": out[rows.angle_labels[0]], "yaw": out[rows.angle_labels[1]], "roll": out[rows.angle_labels[2]]}
        )
    for k, m in rows.splits.items():
        out[k] = _angles_summary(rows.err, mask & m, rows.angle_labels)
    for k, v in rows.scalars.items():
        out[k] = _mean(v[mask])
    for k, (labels, v) in rows.vectors.items():
        means = [_mean(v[mask][:, j]) for j in range(v.shape[1])]
        d = dict(zip(labels, means))
        d["mean"] = float(np.mean(means)) if means and all(m is not None for m in means) else None
        out[k] = d
    for k, m in rows.counts.items():
        out[k] = int((mask & m).sum())
    if rows.reexpressed:
        rx = {}
        for side, m in rows.reexpressed.items():
            rx[side] = "from matrix" if m is None else int((subset & m).sum())
        out["re_expressed"] = rx
    if out["mean"] is None and "frobenius" in rows.scalars:
        out["mean"] = out["frobenius"]
    p = PROTOCOLS.get(name, None)
    if p is not None:
        out["system"] = p.system
        out["source"] = p.source
        out["units"] = p.units
        if p.notes:
            out["notes"] = list(p.notes)
    return out
