"""Both Euler solutions read off written angles equal the ones extracted from the matrix (SciPy as the oracle)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from hpe_cli.metrics.pose_pair import PosePair
from hpe_cli.rotation import solutions
from hpe_cli.rotation.systems import get_system, system_names

ANGLE = st.one_of(
    st.floats(-180, 180, allow_nan=False),
    st.sampled_from([-180.0, 180.0, 90.0, -90.0, 87.0, -87.0, 86.999, 0.0, -0.0, 89.9999999]),
)


def _both_ways(system, a):
    X = system.soa_to_canonical(system.soa_from_angles(a[:, 0], a[:, 1], a[:, 2]))
    fast = PosePair(X, X, system, {"gt": (system, a), "pred": (system, a)}).angles(system, "gt")
    p1, p2, _, _ = system.soa_to_angles(system.soa_from_canonical(X))
    slow = (np.stack(np.broadcast_arrays(*p1), -1), np.stack(np.broadcast_arrays(*p2), -1))
    return X, fast, slow


def _matrix(system, a):
    X = system.soa_to_canonical(system.soa_from_angles(a[:, 0], a[:, 1], a[:, 2]))
    return np.stack([np.stack(np.broadcast_arrays(*row), -1) for row in X], -2)


@pytest.mark.parametrize("name", system_names())
@settings(max_examples=40, deadline=None)
@given(a=arrays(np.float64, (16, 3), elements=ANGLE))
def test_written_primary_equals_matrix_path(name, a):
    system = get_system(name)
    X, (f1, f2), (s1, s2) = _both_ways(system, a)
    fast = solutions.primary_from_written(system, a)
    # the rows read as written are the written numbers exactly, and the matrix path agrees with them
    np.testing.assert_array_equal(f1[fast], a[fast])
    np.testing.assert_allclose(s1[fast], a[fast], atol=1e-9, rtol=0)
    # away from the lock both solutions agree with the matrix path; near it the rotation decides
    lock_free = np.abs(np.cos(np.radians(f1[:, solutions.middle_role(system)]))) > 1e-6
    np.testing.assert_allclose(f1[lock_free], s1[lock_free], atol=1e-9, rtol=0)
    np.testing.assert_allclose(f2[lock_free], s2[lock_free], atol=1e-9, rtol=0)
    # as matrices (the independent check): both triples build the input rotation, compared with SciPy's product
    R = _matrix(system, a)
    for sol in (f1, f2):
        B = _matrix(system, sol)
        rel = Rotation.from_matrix(np.swapaxes(R, -1, -2) @ B).magnitude()
        assert np.degrees(rel).max() < 1e-6


def test_no_shortcut_where_the_written_triple_is_not_primary():
    s = get_system("300w_lp")
    a = np.array([[10.0, 95.0, 20.0], [10.0, 88.0, 0.0], [-180.0, 0.0, 0.0], [200.0, 0.0, 0.0], [5.0, 5.0, 5.0]])
    assert solutions.primary_from_written(s, a).tolist() == [False, False, False, False, True]
    assert not solutions.primary_from_written(get_system("whenet"), a).any()
