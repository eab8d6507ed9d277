"""Generic Euler kernels against SciPy's Rotation (independent oracle), both solutions, gimbal lock."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from hpe_cli.rotation.euler import euler_to_matrix, lock_distance, matrix_to_euler, parse_seq, wrap_180, wrap_pi

TAIT_BRYAN = ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx"]
PROPER = ["xyx", "xzx", "yxy", "yzy", "zxz", "zyz"]
ALL = TAIT_BRYAN + PROPER

angle = st.floats(-np.pi, np.pi, allow_nan=False)
# middle angles at and around the lock: exact, 1e-15 .. 1e-3 rad away
near = st.sampled_from([0.0, 1e-15, 1e-12, 1e-9, 1e-6, 1e-3]).flatmap(lambda d: st.sampled_from([d, -d]))


def _close(A, B, tol=1e-12):
    return np.abs(np.asarray(A) - np.asarray(B)).max() < tol


@pytest.mark.parametrize("seq", ALL)
@given(a=angle, b=angle, c=angle)
def test_matches_scipy_matrix(seq, a, b, c):
    R = euler_to_matrix([a, b, c], seq)
    assert _close(R, Rotation.from_euler(seq.upper(), [a, b, c]).as_matrix())


@pytest.mark.parametrize("seq", ALL)
def test_both_solutions_rebuild_random(seq):
    R = Rotation.random(5000, random_state=7).as_matrix()
    s1, s2, _ = matrix_to_euler(R, seq)
    assert _close(euler_to_matrix(s1, seq), R, 1e-13)
    assert _close(euler_to_matrix(s2, seq), R, 1e-13)
    # solution 1 is SciPy's (away from lock, compared as angles and as matrices)
    ref = Rotation.from_matrix(R).as_euler(seq.upper())
    assert np.abs(wrap_pi(ref - s1)).max() < 1e-9
    for s in (s1, s2):
        assert (s > -np.pi).all() and (s <= np.pi).all()
    if seq[0] == seq[2]:
        assert (s1[:, 1] >= 0).all() and (s2[:, 1] <= 0).all()
    else:
        assert (np.abs(s1[:, 1]) <= np.pi / 2).all()


@pytest.mark.parametrize("seq", ALL)
@given(a=angle, c=angle, d=near, sign=st.sampled_from([1.0, -1.0]))
def test_gimbal_lock_rebuilds(seq, a, c, d, sign):
    b = (0.0 if sign > 0 else np.pi) + d if seq[0] == seq[2] else sign * np.pi / 2 + d
    R = euler_to_matrix([a, b, c], seq)
    s1, s2, lock = matrix_to_euler(R, seq)
    # a split at the lock costs at most ~1e-12 of matrix error; elsewhere a few eps
    assert _close(euler_to_matrix(s1, seq), R, 1e-11)
    assert _close(euler_to_matrix(s2, seq), R, 1e-11)
    assert lock <= abs(np.sin(d)) + 1e-15


def test_lock_split_halves_like_the_paper():
    # at y = +90 in intrinsic xyz only a + c is observable; each half of it
    R = euler_to_matrix([0.3, np.pi / 2, 0.5], "xyz")
    s1, _, lock = matrix_to_euler(R, "xyz")
    assert lock < 1e-15
    assert np.allclose(s1, [0.4, np.pi / 2, 0.4])


def test_lock_distance_is_cos_middle():
    b = np.linspace(-np.pi / 2, np.pi / 2, 11)
    R = euler_to_matrix(np.stack([0.2 + 0 * b, b, -0.4 + 0 * b], -1), "zyx")
    assert np.allclose(lock_distance(R, "zyx"), np.abs(np.cos(b)))


def test_bad_sequences():
    for bad in ["xxy", "ab", "xyzz", "xyy"]:
        with pytest.raises(ValueError, match="expected an Euler sequence"):
            parse_seq(bad)


@given(arrays(np.float64, 20, elements=st.floats(-1e4, 1e4)))
def test_wrap_ranges(x):
    w = wrap_180(x)
    assert (w > -180).all() and (w <= 180).all()
    assert np.allclose(np.cos(np.deg2rad(w)), np.cos(np.deg2rad(x)), atol=1e-9)
    assert wrap_180(np.array([180.0, -180.0, 540.0]))[0] == 180.0 and wrap_180(np.array([-180.0]))[0] == 180.0
