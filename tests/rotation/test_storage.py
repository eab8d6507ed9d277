"""Storage kernels against SciPy's Rotation (rotvec, quaternion both orders, matrix) and hand formulas (6-D)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.rotation.storage import (
    canonical_quaternion,
    matrix4_to_matrix,
    matrix_to_matrix4,
    matrix_to_quaternion,
    matrix_to_rotvec,
    matrix_to_sixd,
    quaternion_to_matrix,
    rotvec_to_matrix,
    sixd_to_matrix,
)

RNG = np.random.default_rng(12)
RAND = Rotation.random(2000, random_state=5)
# near 0, near pi, exactly pi, exactly identity
SPECIAL = Rotation.from_rotvec(
    np.concatenate(
        [
            np.array([[0, 0, 0], [1e-12, 0, 0], [0, 1e-7, -1e-7], [np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi]]),
            RNG.normal(size=(50, 3)) * 1e-6,
            (lambda v: v / np.linalg.norm(v, axis=1, keepdims=True) * (np.pi - 1e-9))(RNG.normal(size=(50, 3))),
            (lambda v: v / np.linalg.norm(v, axis=1, keepdims=True) * (np.pi - 1e-4))(RNG.normal(size=(50, 3))),
        ]
    )
)


def same_rotation(R1, R2):
    return np.abs(R1 - R2).max()


@pytest.mark.parametrize("rots", [RAND, SPECIAL])
def test_rotvec_against_scipy(rots):
    rv = rots.as_rotvec()
    assert same_rotation(rotvec_to_matrix(rv), rots.as_matrix()) < 1e-14
    mine = matrix_to_rotvec(rots.as_matrix())
    assert same_rotation(Rotation.from_rotvec(mine).as_matrix(), rots.as_matrix()) < 1e-14
    assert np.all(np.linalg.norm(mine, axis=1) <= np.pi + 1e-12)
    away = np.linalg.norm(rv, axis=1) < np.pi - 1e-6  # the axis sign at pi is a choice
    assert np.abs(mine[away] - rv[away]).max() < 1e-12


def test_rotvec_tiny_is_exact():
    v = np.array([[1e-9, -2e-9, 3e-9]])
    R = rotvec_to_matrix(v)
    assert np.abs(R - Rotation.from_rotvec(v).as_matrix()).max() < 1e-18
    assert np.abs(matrix_to_rotvec(R) - v).max() < 1e-17


@pytest.mark.parametrize("order", ["wxyz", "xyzw"])
@pytest.mark.parametrize("rots", [RAND, SPECIAL])
def test_quaternion_against_scipy(order, rots):
    q_xyzw = rots.as_quat()  # SciPy: scalar last
    q = q_xyzw if order == "xyzw" else q_xyzw[:, [3, 0, 1, 2]]
    assert same_rotation(quaternion_to_matrix(q, order), rots.as_matrix()) < 1e-14
    assert same_rotation(quaternion_to_matrix(-q, order), rots.as_matrix()) < 1e-14  # q and -q
    mine = matrix_to_quaternion(rots.as_matrix(), order)
    w = mine[:, 0] if order == "wxyz" else mine[:, 3]
    assert (w >= 0).all()
    ref = q * np.where(q[:, 0 if order == "wxyz" else 3] < 0, -1, 1)[:, None]
    assert np.abs(np.abs(mine) - np.abs(ref)).max() < 1e-14
    assert (
        same_rotation(
            Rotation.from_quat(mine if order == "xyzw" else mine[:, [1, 2, 3, 0]]).as_matrix(), rots.as_matrix()
        )
        < 1e-14
    )


def test_quaternion_normalises_and_canonicalises():
    q = np.array([[-2.0, 0, 0, 0], [0, 0, 0, -3.0]])
    assert np.allclose(canonical_quaternion(q), [[1, 0, 0, 0], [0, 0, 0, -1]])
    assert np.allclose(quaternion_to_matrix(q[:1]), np.eye(3))
    with pytest.raises(ValueError, match="expected quaternion order"):
        quaternion_to_matrix(q, "wzyx")


@pytest.mark.parametrize("cols", [(0, 1), (1, 0), (0, 2), (1, 2), (2, 1)])
def test_sixd_round_trip_and_gram_schmidt(cols):
    R = RAND.as_matrix()
    d6 = matrix_to_sixd(R, cols)
    assert np.abs(d6[:, :3] - R[:, :, cols[0]]).max() == 0
    assert same_rotation(sixd_to_matrix(d6, cols), R) < 1e-14
    # a noisy, unnormalised 6-D vector: hand-written Gram-Schmidt (6DRepNet's formula) is the oracle
    noisy = d6 * 3.0 + RNG.normal(scale=0.05, size=d6.shape)
    M = sixd_to_matrix(noisy, cols)
    assert np.abs(np.linalg.det(M) - 1).max() < 1e-12
    assert np.abs(M @ np.swapaxes(M, 1, 2) - np.eye(3)).max() < 1e-12
    if cols == (0, 1):
        x = noisy[:, :3] / np.linalg.norm(noisy[:, :3], axis=1, keepdims=True)
        z = np.cross(x, noisy[:, 3:])
        z /= np.linalg.norm(z, axis=1, keepdims=True)
        y = np.cross(z, x)
        assert np.abs(M - np.stack([x, y, z], -1)).max() < 1e-14


def test_sixd_degenerate_gives_nan():
    M = sixd_to_matrix(np.array([[0, 0, 0, 0, 1, 0], [1, 0, 0, 2, 0, 0]], float))
    assert np.isnan(M).any(axis=(1, 2)).all()


def test_matrix4_block():
    R = RAND.as_matrix()[:5]
    M = matrix_to_matrix4(R, t=np.ones((5, 3)))
    assert M.shape == (5, 4, 4) and np.all(M[:, 3, 3] == 1) and np.all(M[:, :3, 3] == 1)
    assert np.array_equal(matrix4_to_matrix(M), R)


angle = st.floats(-np.pi, np.pi, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 1e-6),
    st.one_of(angle, st.sampled_from([0.0, 1e-12, np.pi, np.pi - 1e-10])),
)
def test_rotvec_quaternion_property(axis, theta):
    v = np.asarray(axis) / np.linalg.norm(axis) * theta
    ref = Rotation.from_rotvec(v).as_matrix()
    assert same_rotation(rotvec_to_matrix(v[None])[0], ref) < 1e-14
    assert same_rotation(rotvec_to_matrix(matrix_to_rotvec(ref[None]))[0], ref) < 1e-14
    assert same_rotation(quaternion_to_matrix(matrix_to_quaternion(ref[None]))[0], ref) < 1e-14
