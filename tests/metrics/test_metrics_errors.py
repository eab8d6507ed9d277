"""Core metrics against SciPy and closed-form identities (hpe_cli.metrics.rotation_errors, align, evaluate)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import canonical_A
from hpe_cli.metrics import rotation_errors as re_
from hpe_cli.metrics.align import mean_offset
from hpe_cli.metrics.evaluate import evaluate
from hpe_cli.rotation.systems import get_system


def _random(n, seed):
    return Rotation.random(n, random_state=seed).as_matrix()


def test_geodesic_matches_scipy_magnitude_including_near_180():
    P = _random(500, 1)
    G = _random(500, 2)
    # add pairs 180 degrees and 1e-7 degrees apart
    flip = Rotation.from_rotvec(np.pi * np.array([[0, 1.0, 0], [1.0, 0, 0]])).as_matrix()
    tiny = Rotation.from_rotvec(np.deg2rad(1e-7) * np.array([[0, 0, 1.0]])).as_matrix()
    P = np.concatenate([P, flip @ G[:2], tiny @ G[:1]])
    G = np.concatenate([G, G[:2], G[:1]])
    oracle = np.rad2deg((Rotation.from_matrix(P) * Rotation.from_matrix(G).inv()).magnitude())
    got = re_.geodesic_deg(P, G)
    np.testing.assert_allclose(got, oracle, atol=1e-9)
    assert got[-1] == pytest.approx(1e-7, rel=1e-3)


def test_geodesic_zero_exactly_when_equal():
    R = _random(300, 3)
    assert np.all(re_.geodesic_deg(R, R) < 1e-9)
    S = Rotation.from_rotvec(np.deg2rad(0.01) * np.array([[0.0, 0.6, 0.8]])).as_matrix() @ R
    assert np.all(re_.geodesic_deg(S, R) > 0.0099)


@given(st.floats(0.0, 180.0), st.floats(-1, 1), st.floats(0, 2 * np.pi))
def test_frobenius_equals_2sqrt2_sin_half_angle(theta, z, phi):
    axis = np.array([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    R = Rotation.from_rotvec(np.deg2rad(theta) * axis).as_matrix()[None]
    G = _random(1, 7)
    # ||I - P G^T||_F with P = R G, written out as the DAD-3DHeads benchmark does
    direct = np.linalg.norm(np.eye(3) - (R @ G)[0] @ G[0].T, "fro")
    expected = 2 * np.sqrt(2) * np.sin(np.deg2rad(theta) / 2)
    assert re_.frobenius(R @ G, G)[0] == pytest.approx(expected, abs=1e-12)
    assert direct == pytest.approx(expected, abs=1e-12)


def test_maev_is_angle_between_columns():
    P, G = _random(200, 4), _random(200, 5)
    oracle = np.rad2deg(np.arccos(np.clip(np.einsum("nij,nij->nj", P, G), -1, 1)))
    np.testing.assert_allclose(re_.maev_deg(P, G), oracle, atol=1e-6)


def test_wrap_abs():
    np.testing.assert_allclose(re_.wrap_abs_deg([0, 190, -190, 360, 540, -179.5]), [0, 170, 170, 0, 180, 179.5])


def _opal23_compute_mae(ann_matrices, pred_matrices):
    """opal23 test/evaluator.py Evaluator.compute_mae, written from its description (YPR order out)."""
    ann = Rotation.from_matrix(ann_matrices).as_euler("XYZ", degrees=True)
    pred = Rotation.from_matrix(pred_matrices).as_euler("XYZ", degrees=True)
    ann[:, [0, 1]] = ann[:, [1, 0]]
    pred[:, [0, 1]] = pred[:, [1, 0]]
    sign = np.sign(pred)
    wrap = np.stack([180 - pred[:, 0], pred[:, 1] - sign[:, 1] * 180, pred[:, 2] - sign[:, 2] * 180], -1)
    wrap[wrap > 180] -= 360
    wrap[wrap < -180] += 360
    e = np.abs(ann - pred)
    ew = np.abs(ann - wrap)
    use = ew.mean(-1) < e.mean(-1)
    e[use] = ew[use]
    return np.minimum(e, 360 - e)


def test_mae_best_of_two_is_opal23_in_300w_lp():
    rng = np.random.default_rng(8)
    G = canonical_A(np.c_[rng.uniform(-80, 80, 400), rng.uniform(-85, 85, 400), rng.uniform(-80, 80, 400)])
    noise = Rotation.from_rotvec(np.deg2rad(rng.normal(0, 20, (400, 3)))).as_matrix()
    P = noise @ G
    ypr = _opal23_compute_mae(G, P)  # A = Rx(-p) Ry(-y) Rz(-r): XYZ gives -(p, y, r); |d| ignores the sign
    r = evaluate(P, G, pred_system="300w_lp", gt_system="300w_lp", protocols=["opal23"], columns="matrix")
    m = r["metrics"]["mae_best_of_two"]
    assert m["yaw"] == pytest.approx(ypr[:, 0].mean(), abs=1e-9)
    assert m["pitch"] == pytest.approx(ypr[:, 1].mean(), abs=1e-9)
    assert m["roll"] == pytest.approx(ypr[:, 2].mean(), abs=1e-9)
    assert r["protocols"]["opal23"]["mean"] == pytest.approx(ypr.mean(), abs=1e-9)
    ge = np.rad2deg(np.arccos(np.clip((np.trace(G @ P.transpose(0, 2, 1), axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert r["protocols"]["opal23"]["geodesic"] == pytest.approx(ge.mean(), abs=1e-6)


@pytest.mark.parametrize("systems", [("6drepnet", "whenet"), ("opencv", "biwi"), ("scipy_zyx", "3ddfa_v2")])
def test_same_pair_in_different_systems_same_geodesic_and_maev(systems):
    P, G = _random(300, 11), _random(300, 12)
    base = evaluate(P, G, pred_system="300w_lp", gt_system="300w_lp", protocols=[], columns="matrix")
    a, b = (get_system(s) for s in systems)
    # state the same rotations as angles of other systems (primary solutions)
    pa, _, _, _ = a.to_angles(a.from_canonical(P))
    gb, _, _, _ = b.to_angles(b.from_canonical(G))
    other = evaluate(pa, gb, pred_system=a, gt_system=b, protocols=[])
    for k in ("mean", "median", "max"):
        assert other["metrics"]["geodesic"][k] == pytest.approx(base["metrics"]["geodesic"][k], abs=1e-8)
    for k in ("left", "down", "front"):
        assert other["metrics"]["maev"][k] == pytest.approx(base["metrics"]["maev"][k], abs=1e-8)
    assert other["metrics"]["frobenius"]["mean"] == pytest.approx(base["metrics"]["frobenius"]["mean"], abs=1e-10)


def test_align_mean_recovers_constant_offset():
    rng = np.random.default_rng(21)
    G = _random(2000, 22)
    Q = Rotation.from_euler("xyz", [4.0, -7.0, 2.5], degrees=True).as_matrix()
    P = Q @ G
    np.testing.assert_allclose(mean_offset(P, G), Q, atol=1e-12)
    noisy = Rotation.from_rotvec(np.deg2rad(rng.normal(0, 2, (2000, 3)))).as_matrix() @ P
    r = evaluate(noisy, G, pred_system="300w_lp", gt_system="300w_lp", protocols=[], align="mean", columns="matrix")
    angle = np.rad2deg(Rotation.from_matrix(Q).magnitude())
    assert r["align"]["offset_deg"] == pytest.approx(angle, abs=0.15)
    assert r["metrics"]["geodesic"]["mean"] < r["align"]["before"]["metrics"]["geodesic"]["mean"] - 3
    exact = evaluate(
        P, G, pred_system="300w_lp", gt_system="300w_lp", protocols=["hopenet"], align="mean", columns="matrix"
    )
    assert exact["metrics"]["geodesic"]["max"] < 1e-6
    assert exact["protocols"]["hopenet"]["mean"] < 1e-6
    # the offset in GT-system angles rebuilds Q
    qa = exact["align"]["offset_angles"]
    np.testing.assert_allclose(canonical_A([[qa["pitch"], qa["yaw"], qa["roll"]]])[0], Q, atol=1e-9)


def test_api_counts_invalid_rows_and_rejects_bad_shapes():
    G = _random(5, 30)
    P = G.copy()
    P[1, 0, 0] = np.nan
    P[2] = P[2] * np.array([1, 1, -1])  # det -1
    r = evaluate(P, G, pred_system="300w_lp", gt_system="300w_lp", columns="matrix", protocols=["hopenet"])
    assert r["n"] == {"gt": 5, "pred": 5, "pairs": 3, "missing": 0, "invalid": 2}
    assert r["metrics"]["geodesic"]["max"] < 1e-9
    with pytest.raises(ValueError, match="expected as many"):
        evaluate(P[:4], G, pred_system="300w_lp", gt_system="300w_lp")
    with pytest.raises(ValueError, match="unknown protocol"):
        evaluate(P, G, pred_system="300w_lp", gt_system="300w_lp", protocols=["nope"])


def test_rotvec_matches_cv2_rodrigues_up_to_180():
    import cv2

    R = _random(1000, 40)
    ax = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    near = Rotation.from_rotvec(np.outer([np.pi - 1e-9, -(np.pi - 1e-5), np.pi / 2, 1e-3], ax)).as_matrix()
    R = np.concatenate([R, near])
    oracle = np.array([cv2.Rodrigues(r)[0].ravel() for r in R]) * 180 / np.pi
    np.testing.assert_allclose(re_.rotvec_deg(R), oracle, atol=1e-6)
