"""Batched similarity fit against exact transforms, SciPy's Kabsch solver and the real Panoptic faces."""

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.geometry.reference import panoptic_pairs, reference_head
from hpe_cli.geometry.similarity import fit_similarity


def _apply(s, R, t, X):
    return s[:, None, None] * np.einsum("nij,npj->npi", R, X) + t[:, None, :]


@given(st.integers(0, 2**32 - 1), st.integers(3, 20))
def test_recovers_exact_similarity(seed, P):
    rng = np.random.default_rng(seed)
    N = 8
    src = rng.normal(size=(N, P, 3)) * rng.uniform(0.5, 20)
    R = Rotation.random(N, random_state=seed).as_matrix()
    s = rng.uniform(0.01, 100, N)
    t = rng.normal(size=(N, 3)) * 500
    fit = fit_similarity(src, _apply(s, R, t, src))
    np.testing.assert_allclose(fit["scale"], s, rtol=1e-9)
    np.testing.assert_allclose(fit["R"], R, atol=1e-9)
    np.testing.assert_allclose(fit["t"], t, atol=1e-6 * (1 + np.abs(t).max()))
    assert np.all(fit["rmse"] < 1e-8 * s * np.abs(src).max())
    assert np.all(fit["n_pairs"] == P)
    assert np.allclose(np.linalg.det(fit["R"]), 1.0)


def test_rotation_matches_scipy_kabsch_with_noise():
    rng = np.random.default_rng(1)
    N, P = 50, 14
    src = rng.normal(size=(N, P, 3)) * 5
    R = Rotation.random(N, random_state=2).as_matrix()
    dst = _apply(np.full(N, 1.3), R, rng.normal(size=(N, 3)), src) + rng.normal(size=(N, P, 3)) * 0.3
    fit = fit_similarity(src, dst)
    for n in range(N):
        a = dst[n] - dst[n].mean(0)
        b = src[n] - src[n].mean(0)
        ref, _ = Rotation.align_vectors(a, b)  # the rotation part of the least-squares similarity
        assert np.abs(ref.as_matrix() - fit["R"][n]).max() < 1e-9
    # residual really is the RMS distance of the fitted points
    pred = _apply(fit["scale"], fit["R"], fit["t"], src)
    np.testing.assert_allclose(fit["rmse"], np.sqrt(((pred - dst) ** 2).sum(-1).mean(-1)), rtol=1e-10)


def test_least_squares_optimality():
    """Perturbing scale, rotation or translation never lowers the residual."""
    rng = np.random.default_rng(3)
    src = rng.normal(size=(1, 10, 3))
    dst = rng.normal(size=(1, 10, 3))
    fit = fit_similarity(src, dst)
    base = fit["rmse"][0]
    for _ in range(200):
        dR = Rotation.from_rotvec(rng.normal(size=3) * 0.05).as_matrix()
        s = fit["scale"] * (1 + rng.normal() * 0.05)
        t = fit["t"] + rng.normal(size=3) * 0.05
        pred = _apply(s, dR[None] @ fit["R"], t, src)
        assert np.sqrt(((pred - dst) ** 2).sum(-1).mean()) >= base - 1e-12


def test_reflection_is_never_returned():
    """A mirrored target: the best orthogonal map is a reflection, the fit must stay proper."""
    src = np.random.default_rng(4).normal(size=(1, 6, 3))
    fit = fit_similarity(src, src * np.array([-1.0, 1, 1]))
    assert np.isclose(np.linalg.det(fit["R"][0]), 1.0)
    assert fit["rmse"][0] > 0.1


def test_mask_nan_and_too_few_pairs():
    rng = np.random.default_rng(5)
    src = rng.normal(size=(4, 6, 3))
    R = Rotation.random(4, random_state=6).as_matrix()
    dst = _apply(np.ones(4), R, np.zeros((4, 3)), src)
    dst[0, 0] = [100, 100, 100]  # an outlier, masked out below
    dst[1, 1] = np.nan  # non-finite: unusable without being masked
    mask = np.ones((4, 6), bool)
    mask[0, 0] = False
    mask[2, 2:] = False  # 2 pairs only
    src[3] = src[3, :1] + np.outer(np.arange(6), [1.0, 2, 3])  # collinear source
    fit = fit_similarity(src, dst, mask)
    assert list(fit["n_pairs"]) == [5, 5, 2, 6]
    np.testing.assert_allclose(fit["R"][0], R[0], atol=1e-12)
    np.testing.assert_allclose(fit["R"][1], R[1], atol=1e-12)
    assert np.isnan(fit["R"][2]).all() and np.isnan(fit["scale"][2]) and np.isnan(fit["rmse"][2])
    assert np.isnan(fit["R"][3]).all()


def test_shape_errors():
    with pytest.raises(ValueError, match="expected src and dst"):
        fit_similarity(np.zeros((2, 5, 3)), np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match="mask"):
        fit_similarity(np.zeros((2, 5, 3)), np.zeros((2, 5, 3)), np.ones((2, 4), bool))


def test_real_face_6577_person_2(realdata):
    """The issue's garbage fit: RMSE ~5.9 cm, scale ~1.95, from 8 of 14 pairs."""
    f = json.loads((realdata / "panoptic_160906_pizza1" / "hdFace3d" / "faceRecon3D_hd00006577.json").read_text())
    face = next(p for p in f["people"] if p["id"] == 2)["face70"]
    lm = np.asarray(face["landmarks"]).reshape(70, 3)
    score = np.asarray(face["averageScore"])
    f70, head = panoptic_pairs()
    fit = fit_similarity(reference_head()[head][None], lm[f70][None], (score[f70] > 0.1)[None])
    assert fit["n_pairs"][0] == 8
    assert abs(fit["rmse"][0] - 5.87) < 0.05
    assert abs(fit["scale"][0] - 1.955) < 0.01
