"""Views and time, the pure maths: SciPy oracles and constructed cases."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.metrics import consistency as mc


def _deg(A, B):
    return np.rad2deg((Rotation.from_matrix(A) * Rotation.from_matrix(B).inv()).magnitude())


@given(st.integers(0, 2**31 - 1), st.integers(3, 12))
def test_chordal_l1_mean_ignores_a_minority_of_outliers(seed, n_good):
    rng = np.random.default_rng(seed)
    C = Rotation.random(random_state=seed).as_matrix()
    good = [C] * n_good
    bad = Rotation.random(n_good // 2 - (n_good % 2 == 0), random_state=seed + 1).as_matrix()
    R = np.concatenate([np.array(good), bad.reshape(-1, 3, 3)])
    R = R[rng.permutation(len(R))]
    M = mc.chordal_l1_mean(R, np.array([0]), iterations=60)
    assert _deg(M[0], C) < 1e-3


def test_chordal_l1_mean_of_a_symmetric_cloud_is_its_centre():
    C = Rotation.from_euler("xyz", [10, -40, 5], degrees=True)
    offs = Rotation.from_rotvec(np.deg2rad(3) * np.vstack([np.eye(3), -np.eye(3)]))
    R = (C * offs).as_matrix()
    starts = np.array([0])
    M = mc.chordal_l1_mean(R, starts)
    assert _deg(M[0], C.as_matrix()) < 1e-6
    # the chordal L2 mean of SciPy agrees on a symmetric cloud
    assert _deg(M[0], Rotation.from_matrix(R).mean().as_matrix()) < 1e-6


def test_view_consensus_recovers_a_turned_camera():
    rng = np.random.default_rng(0)
    E = np.diag([1.0, -1.0, -1.0])
    n_cam, n_t = 6, 40
    cams = Rotation.random(n_cam, random_state=1).as_matrix()
    heads = Rotation.random(n_t, random_state=2).as_matrix()
    off = Rotation.from_rotvec(np.deg2rad([1.0, -2.0, 0.5])).as_matrix()
    A, R, code = [], [], []
    for t in range(n_t):
        for c in range(n_cam):
            a = E @ cams[c] @ heads[t]
            A.append(off @ a if c == 2 else a)
            R.append(cams[c])
            code.append(c)
    A, R, code = np.array(A), np.array(R), np.array(code)
    starts = np.arange(0, len(A), n_cam)
    res = mc.view_consensus(A, R, starts)
    assert np.allclose(res["angle"][code != 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(res["angle"][code == 2], np.linalg.norm([1.0, -2.0, 0.5]), atol=1e-6)
    o = mc.camera_offsets(res["offset"], code)
    k = list(o["codes"]).index(2)
    np.testing.assert_allclose(o["median"][k], [1.0, -2.0, 0.5], atol=1e-6)
    assert o["significant"].tolist() == [c == 2 for c in o["codes"]]
    del rng


def test_steady_turn_is_not_a_jump_and_a_glitch_is():
    n = 30
    yaw = np.linspace(-80, 80, n)  # 5.5 deg per frame, steady
    A = Rotation.from_euler("y", yaw[:, None], degrees=True).as_matrix()
    frames = np.arange(n)
    r = mc.temporal_jumps(A, frames, np.array([0]), max_gap=10)
    assert np.nanmax(r["rate"]) < 1e-6
    assert np.isnan(r["rate"][[0, -1]]).all()
    A[15] = Rotation.from_euler("x", 20, degrees=True).as_matrix() @ A[15]
    r = mc.temporal_jumps(A, frames, np.array([0]), max_gap=10)
    assert abs(r["rate"][15] - 20.0) < 1e-6
    others = np.delete(r["rate"], 15)
    assert np.nanmax(others) < 1e-6  # the neighbours are not flagged with it


def test_frame_gaps_scale_the_rate_and_far_neighbours_are_not_used():
    A = Rotation.from_euler("y", [[0], [10], [0], [0]], degrees=True).as_matrix()
    r = mc.temporal_jumps(A, np.array([0, 2, 4, 30]), np.array([0]), max_gap=10)
    np.testing.assert_allclose(r["rate"][1], 5.0)  # 10 deg off, neighbours 2 frames away
    assert np.isnan(r["rate"][2])  # next neighbour 26 frames away


def test_expected_landmark_angle_grows_with_yaw():
    e = mc.expected_landmark_angle([0, 45, 90, 120])
    np.testing.assert_allclose(
        e, [mc.LM_EXPECTED_0, mc.LM_EXPECTED_0 + mc.LM_EXPECTED_90 / 4] + [mc.LM_EXPECTED_0 + mc.LM_EXPECTED_90] * 2
    )


def test_combined_score_is_nan_only_without_evidence():
    s = mc.combined_score([np.nan, 1.0, np.nan], [np.nan, 4.0, 2.0])
    assert np.isnan(s[0]) and s[1] == 4.0 and s[2] == 2.0


def test_expected_angle_is_fitted_robustly_to_the_data():
    rng = np.random.default_rng(5)
    yaw = rng.uniform(0, 90, 5000)
    typical = 3.0 + 6.0 * (yaw / 90) ** 2
    angle = typical * rng.uniform(0.5, 1.5, yaw.size)  # median = typical
    angle[rng.random(yaw.size) < 0.2] = 60.0  # a fifth of the labels wrong
    f = mc.fit_expected_landmark_angle(yaw, angle)
    assert f["source"] == "fitted on 5000 rows"
    assert abs(f["a"] - 3.0) < 1.0 and abs(f["b"] - 6.0) < 2.5
    few = mc.fit_expected_landmark_angle(yaw[:100], angle[:100])
    assert few == {"a": mc.LM_EXPECTED_0, "b": mc.LM_EXPECTED_90, "source": "constants"}
