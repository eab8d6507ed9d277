"""The weak-perspective landmark fit: exact on synthetic projections (SciPy oracle), close on the real files."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.geometry.landmark_pose import (
    MIN_POINTS,
    SCHEME_SIZES,
    fit_landmark_pose,
    landmark_disagreement,
    scheme_model,
)
from hpe_cli.geometry.template import reference_template
from tests.conftest import canonical_A


def _angle_deg(A, B):
    """Independent geodesic: SciPy's magnitude of A B^T."""
    return np.rad2deg(Rotation.from_matrix(np.asarray(A) @ np.swapaxes(B, -1, -2)).magnitude())


def _project(A, scale, t, points):
    """u = s (A X)_x + t_u, v = -s (A X)_y + t_v, written out here (image y down)."""
    Y = np.einsum("nij,lj->nli", A, points)
    return np.stack([scale[:, None] * Y[..., 0] + t[:, None, 0], -scale[:, None] * Y[..., 1] + t[:, None, 1]], -1)


def _scheme_points(scheme):
    T = reference_template()
    if scheme == "aflw21":
        idx = {0: 17, 1: 19, 2: 21, 3: 22, 4: 24, 5: 26, 6: 36, 8: 39, 9: 42, 11: 45, 13: 31, 14: 30, 15: 35}
        idx.update({17: 48, 19: 54, 20: 8})
        P = np.full((21, 3), np.nan)
        for a, b in idx.items():
            P[a] = T[b]
        P[7] = T[[37, 38, 40, 41]].mean(0)
        P[10] = T[[43, 44, 46, 47]].mean(0)
        P[18] = T[[62, 66]].mean(0)
        return P
    P = T.copy()
    if scheme == "face70":
        P = np.concatenate([P, T[36:42].mean(0, keepdims=True), T[42:48].mean(0, keepdims=True)])
    P[:17] = np.nan  # jaw contour not used
    return P


@pytest.mark.parametrize("scheme", ["ibug68", "face70", "aflw21"])
def test_model_points_match_the_documented_pairs(scheme):
    pts, used = scheme_model(scheme)
    assert pts.shape == (SCHEME_SIZES[scheme], 3)
    np.testing.assert_allclose(pts, _scheme_points(scheme), equal_nan=True)
    assert used.sum() == {"ibug68": 51, "face70": 53, "aflw21": 19}[scheme]


@pytest.mark.parametrize("scheme", ["ibug68", "face70", "aflw21"])
def test_noise_free_projections_are_recovered_over_the_whole_sphere(scheme):
    rng = np.random.default_rng(1)
    N = 2000
    R = Rotation.random(N, random_state=2)
    A = R.as_matrix()
    scale = rng.uniform(20, 400, N)
    t = rng.uniform(-100, 600, (N, 2))
    uv = _project(A, scale, t, _scheme_points(scheme))
    fit = fit_landmark_pose(uv, scheme)
    assert (fit["reason"] == "").all()
    assert _angle_deg(A, fit["A"]).max() < 1e-6
    np.testing.assert_allclose(np.linalg.det(fit["A"]), 1.0, atol=1e-12)
    np.testing.assert_allclose(fit["scale"], scale, rtol=1e-9)
    assert np.nanmax(fit["residual"]) < 1e-6


def test_profile_and_extreme_poses_from_angles():
    # yaw up to +-90 and beyond, with pitch and roll: labels built by SPEC's formula, not by hpe
    pyr = np.array(
        [[0, 90, 0], [0, -90, 0], [10, 89.9, -5], [-30, -75, 20], [45, 60, 30], [-60, 0, 0], [0, 120, 0], [80, 10, 170]]
    )
    A = canonical_A(pyr)
    uv = _project(A, np.full(len(A), 150.0), np.full((len(A), 2), 225.0), _scheme_points("ibug68"))
    fit = fit_landmark_pose(uv, "ibug68")
    assert _angle_deg(A, fit["A"]).max() < 1e-6


@given(st.integers(0, 2**31 - 1), st.integers(MIN_POINTS, 51))
def test_any_visible_subset_of_enough_points(seed, k):
    rng = np.random.default_rng(seed)
    A = Rotation.random(1, random_state=seed).as_matrix()
    uv = _project(A, np.array([100.0]), np.array([[50.0, 60.0]]), _scheme_points("ibug68"))
    hide = rng.permutation(np.arange(17, 68))[: 51 - k]
    uv[0, hide] = np.nan if seed % 2 else -1.0  # NaN, or AFLW's -1
    fit = fit_landmark_pose(uv, "ibug68")
    if fit["reason"][0]:  # a few points can be (nearly) coplanar or collinear: then not fitted, never wrong
        assert fit["reason"][0].startswith("degenerate")
        assert np.isnan(fit["A"]).all()
        return
    assert fit["n_points"][0] == k
    assert _angle_deg(A, fit["A"])[0] < 1e-6


def test_too_few_points_and_collinear_points_are_not_fitted():
    A = np.eye(3)[None].repeat(3, 0)
    uv = _project(A, np.full(3, 100.0), np.zeros((3, 2)), _scheme_points("ibug68"))
    uv[0, 17 + MIN_POINTS - 1 :] = np.nan  # 5 points left
    uv[1] = np.nan
    uv[1, 27:31] = [[0, 0], [0, 10], [0, 20], [0, 30]]  # the nose bridge: 4 points...
    uv[1, 51:55] = [[0, 40], [0, 50], [0, 60], [0, 70]]  # ...and 4 more, all on one line
    fit = fit_landmark_pose(uv, "ibug68")
    assert fit["reason"][0] == f"fewer than {MIN_POINTS} visible landmarks"
    assert fit["reason"][1].startswith("degenerate")
    assert fit["reason"][2] == ""
    assert np.isnan(fit["A"][:2]).all() and np.isnan(fit["residual"][:2]).all()


def test_wrong_shape_is_refused():
    with pytest.raises(ValueError, match=r"expected landmarks of shape \(N, 21, 2\)"):
        fit_landmark_pose(np.zeros((2, 68, 2)), "aflw21")
    with pytest.raises(ValueError, match="expected a landmark scheme"):
        fit_landmark_pose(np.zeros((2, 68, 2)), "dlib")


def test_noise_gives_a_small_angle_and_residual():
    rng = np.random.default_rng(3)
    A = Rotation.random(500, random_state=4).as_matrix()
    # keep faces that show their front (z of the face towards the camera)
    A = A[A[:, 2, 2] > 0.3]
    uv = _project(A, np.full(len(A), 200.0), np.full((len(A), 2), 225.0), _scheme_points("ibug68"))
    iod = 200.0 * np.linalg.norm(reference_template()[45] - reference_template()[36])
    uv += rng.normal(0, 0.02 * iod, uv.shape)  # 2% of the inter-ocular distance
    fit = fit_landmark_pose(uv, "ibug68")
    ang = _angle_deg(A, fit["A"])
    assert np.median(ang) < 2.0
    assert 0.01 < np.median(fit["residual"]) < 0.04


def _aflw(realdata):
    from hpe_cli.datasets.mat import read_mat

    files = sorted((realdata / "aflw2000_prnet").glob("*.mat"))
    recs = [read_mat(f) for f in files]
    return np.array([r["pose"][:3] for r in recs]), np.stack([r["pt2d"].T for r in recs]), recs


def test_aflw2000_manual_points_agree_with_the_labels(realdata):
    pyr, uv, _ = _aflw(realdata)
    out = landmark_disagreement(canonical_A(pyr), uv, "aflw21")
    assert (out["reason"] == "").all()
    # 16 files: median 6.7 deg; the worst (image02420, yaw 71, 12 visible points) 29 deg
    assert np.median(out["angle"]) < 10.0
    assert np.median(out["residual"]) < 0.1


def test_aflw2000_fitted_68_points_agree_with_the_labels(realdata):
    pyr, _, recs = _aflw(realdata)
    uv = np.stack([r["pt3d_68"][:2].T for r in recs])
    out = landmark_disagreement(canonical_A(pyr), uv, "ibug68")
    assert np.median(out["angle"]) < 5.0  # 3.5 deg
    assert out["angle"].max() < 8.0


def test_300wlp_68_points_agree_with_the_label(realdata):
    from hpe_cli.datasets.mat import read_mat

    r = read_mat(realdata / "300wlp_face3d" / "IBUG_image_008_1_0.mat")
    out = landmark_disagreement(canonical_A(r["pose"][None, :3]), r["pt2d"].T[None], "ibug68")
    assert out["angle"][0] < 6.0  # 3.7 deg at yaw -44


def test_aflw2000_labels_turned_by_30_deg_are_30_deg_from_the_evidence(realdata):
    pyr, uv, _ = _aflw(realdata)
    A = canonical_A(pyr)
    turn = Rotation.from_rotvec(np.deg2rad(30) * np.array([0.0, 1.0, 0.0])).as_matrix()
    out = landmark_disagreement(turn @ A, uv, "aflw21")
    base = landmark_disagreement(A, uv, "aflw21")
    good = base["angle"] < 10
    assert np.all(np.abs(out["angle"][good] - 30.0) < 10.0)
