"""Pure audit checks (hpe_cli.rotation.audit) against SciPy and SPEC.md's worked examples."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.rotation import get_system, system_from_dict
from hpe_cli.rotation.audit import CHECKS, audit_angles, audit_matrices, duplicate_first

HELEN = (-16.0909, -89.99858, -6.8545)  # 300W-LP HELEN_2375918801_1_14 (SPEC §2)


def scipy_300wlp(pyr):
    """SPEC §2: A = (Rz(r) Ry(y) Rx(p)).T, built with SciPy's intrinsic 'ZYX'."""
    p, y, r = np.asarray(pyr, float).T
    return np.swapaxes(Rotation.from_euler("ZYX", np.stack([r, y, p], -1), degrees=True).as_matrix(), -1, -2)


def scipy_primary(pyr):
    """300W-LP solution 1 (|yaw| <= 90) of a triple, via SciPy's own decomposition."""
    G = np.swapaxes(scipy_300wlp(pyr), -1, -2)
    r, y, p = Rotation.from_matrix(G).as_euler("ZYX", degrees=True).T
    return np.stack([p, y, r], -1)


def flags(res, i):
    return {c for c in CHECKS if res[c][i]}


def test_helen_is_locked_and_near():
    res = audit_angles([HELEN], "300w_lp")
    assert flags(res, 0) == {"gimbal_lock", "near_gimbal"}
    # SPEC: R[0,2] is 1 - 3e-10, so |cos yaw| ~ 2.5e-5 rad
    assert res["lock_distance"][0] == pytest.approx(np.cos(np.deg2rad(HELEN[1])), rel=1e-6)


def test_near_gimbal_threshold_and_superset():
    pyr = [[0, 89.5, 0], [0, -89.2, 3], [0, 88.9, 0], [5, 90, 7], [0, 10, 0]]
    res = audit_angles(pyr, "300w_lp", near_tol_deg=1.0)
    assert res["near_gimbal"].tolist() == [True, True, False, True, False]
    assert res["gimbal_lock"].tolist() == [False, False, False, True, False]
    # near_gimbal always includes the locked rows, even with a tiny tolerance
    res0 = audit_angles(pyr, "300w_lp", near_tol_deg=0.0)
    assert res0["near_gimbal"].tolist() == res0["gimbal_lock"].tolist()
    assert audit_angles(pyr, "300w_lp", near_tol_deg=1.2)["near_gimbal"].tolist() == [True, True, True, True, False]


def test_yaw_120_is_non_canonical_and_out_of_range():
    res = audit_angles([[10, 120, 5]], "300w_lp")
    assert flags(res, 0) == {"non_canonical", "out_of_range"}
    # its primary solution (p - 180, 60, r - 180) is the same rotation and raises nothing
    np.testing.assert_allclose(scipy_300wlp([[10, 120, 5]]), scipy_300wlp([[-170, 60, -175]]), atol=1e-12)
    assert flags(audit_angles([[-170, 60, -175]], "300w_lp"), 0) == set()


def test_whenet_primary_is_full_range_yaw():
    res = audit_angles([[0, 120, 0], [180, 60, 180], [20, -150, 10]], "whenet")
    assert flags(res, 0) == set()
    assert flags(res, 1) == {"non_canonical", "out_of_range"}  # pitch 180 is outside whenet's (-90, 90)
    assert flags(res, 2) == set()


def test_out_of_range_boundaries():
    res = audit_angles([[0, 0, 180], [0, 0, -180], [0, 0, 270], [0, 90.5, 0], [0, -90, 0]], "300w_lp")
    assert res["out_of_range"].tolist() == [False, True, True, True, False]
    # 270 wraps to -90, which is the primary roll: a range problem, not another solution
    assert not res["non_canonical"][2]
    assert res["non_canonical"][3]


def test_non_finite_rows_get_no_other_flag():
    res = audit_angles([[np.nan, 0, 0], [0, np.inf, 0], [0, 0, -np.inf], [1, 2, 3]], "300w_lp")
    assert res["non_finite"].tolist() == [True, True, True, False]
    for c in CHECKS:
        if c != "non_finite":
            assert not res[c].any(), c


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-180, 180, allow_nan=False)] * 3), min_size=1, max_size=20))
def test_non_canonical_matches_scipy(triples):
    pyr = np.array(triples, dtype=float)
    res = audit_angles(pyr, "300w_lp")
    prim = scipy_primary(pyr)
    d = np.abs(((pyr - prim) + 180) % 360 - 180).max(axis=1)
    lock = np.abs(np.cos(np.deg2rad(pyr[:, 1])))
    clear = (lock > 1e-3) & ((d < 1e-7) | (d > 1e-3))  # away from the lock and from SciPy's own rounding
    expect = d > 1e-6
    assert (res["non_canonical"][clear] == expect[clear]).all()
    assert not res["non_canonical"][res["gimbal_lock"]].any()
    # SciPy's triple is always canonical (except at the lock, where it is not evaluated)
    res2 = audit_angles(prim, "300w_lp")
    assert not res2["non_canonical"][lock > 1e-3].any()


def test_matrix_checks():
    good = scipy_300wlp([[10, 20, 30]])[0]
    helen = scipy_300wlp([HELEN])[0]
    whenet_bad = scipy_300wlp([[120, 10, 30]])[0]  # no solution with |p| < 90 and |r| < 90
    refl = good @ np.diag([1.0, 1.0, -1.0])
    scaled = 1.01 * good
    nan = good.copy()
    nan[1, 1] = np.nan
    R = np.stack([good, helen, whenet_bad, refl, scaled, nan])
    res = audit_matrices(R, "300w_lp")
    assert [flags(res, i) for i in range(6)] == [
        set(),
        {"gimbal_lock", "near_gimbal"},
        set(),
        {"not_rotation"},
        {"not_rotation"},
        {"non_finite"},
    ]
    assert not res["non_canonical"].any()
    resw = audit_matrices(R[:3], "whenet")
    assert flags(resw, 2) == {"out_of_range"}
    np.testing.assert_allclose(res["primary"][0], [10, 20, 30], atol=1e-9)


def test_matrix_input_of_another_system():
    # 6DRepNet stores G = A.T (SPEC §3): the same label must give the same flags
    A = scipy_300wlp([[10, 20, 30], list(HELEN), [0, 89.5, 0]])
    res = audit_matrices(np.swapaxes(A, -1, -2), "6drepnet")
    assert res["gimbal_lock"].tolist() == [False, True, False]
    assert res["near_gimbal"].tolist() == [False, True, True]


def test_proper_euler_lock_is_sin_of_middle_angle():
    zxz = system_from_dict(
        {
            "name": "zxz",
            "turns": [{"angle": "yaw", "axis": "z"}, {"angle": "pitch", "axis": "x"}, {"angle": "roll", "axis": "z"}],
        }
    )
    res = audit_angles([[0.5, 10, 20], [30, 10, 20], [179.5, 5, 5]], zxz)
    assert res["near_gimbal"].tolist() == [True, False, True]


def test_duplicate_first_matches_python():
    rng = np.random.default_rng(1)
    keys = rng.integers(0, 6, size=(300, 2)).astype(np.uint64)
    seen, expect = {}, []
    for i, k in enumerate(map(tuple, keys)):
        expect.append(seen.setdefault(k, i))
    np.testing.assert_array_equal(duplicate_first(keys), expect)
    # keys whose first column decides the rest (the fast path for hashes)
    keys2 = np.column_stack([keys[:, 0], keys[:, 0] * 7 + 1])
    seen, expect2 = {}, []
    for i, k in enumerate(map(tuple, keys2)):
        expect2.append(seen.setdefault(k, i))
    np.testing.assert_array_equal(duplicate_first(keys2), expect2)
    assert duplicate_first(np.zeros((0, 2), np.uint64)).size == 0
    np.testing.assert_array_equal(duplicate_first(np.array([5, 5, 5], np.uint64)), [0, 0, 0])


def test_vectorised_shapes():
    system = get_system("300w_lp")
    res = audit_angles(np.zeros((0, 3)), system)
    assert all(res[c].shape == (0,) for c in CHECKS)


def test_audit_columns_equal_array_functions():
    """The column kernels give the same masks as audit_angles / audit_matrices (the reference)."""
    from hpe_cli.rotation.audit import audit_angles, audit_columns, audit_matrices

    rng = np.random.default_rng(3)
    n = 3000
    pyr = np.c_[rng.uniform(-200, 200, n), rng.uniform(-100, 100, n), rng.uniform(-200, 200, n)]
    pyr[:50, 1] = 90.0  # locked
    pyr[50:100, 1] = 89.5  # near
    pyr[100:110] = np.nan
    pyr[110, 2] = np.inf
    for name in ("300w_lp", "whenet", "6drepnet"):
        ref = audit_angles(pyr, name)
        got = audit_columns([pyr[:, 0], pyr[:, 1], pyr[:, 2]], name, "angles")
        for k in ref:
            assert np.array_equal(ref[k], got[k], equal_nan=True), (name, k)
        sys_ = get_system(name)
        R = sys_.from_angles(np.nan_to_num(pyr))
        R[:5] *= 2.0
        R[5:8] = R[5:8] @ np.diag([1.0, 1, -1])
        R[8, 0, 0] = np.nan
        ref = audit_matrices(R, name)
        got = audit_columns([np.ascontiguousarray(R[:, i, j]) for i in range(3) for j in range(3)], name, "matrix")
        for k in ref:
            assert np.array_equal(ref[k], got[k], equal_nan=True), (name, k)


@pytest.mark.parametrize("kernel", ["numpy", "C"])
@pytest.mark.parametrize("near", [1.0, 0.0, 45.0, 89.95, 90.0, 120.0, -3.0])
def test_screened_angle_flags_equal_round_trip(near, kernel, monkeypatch):
    """The screened angle checks (the middle angle's distance from the lock, no cosine; numpy's passes or the
    compiled kernel) give the round trip's masks bit for bit, on every built-in system, with rows at and around
    the lock and near-gimbal thresholds (for several near-gimbal tolerances, some past 90 degrees), the +-90
    boundary, +-180, out-of-range and huge angles."""
    from hpe_cli.native import kernels
    from hpe_cli.rotation.audit import audit_columns, screen_applies
    from hpe_cli.rotation.systems import system_names

    if kernel == "numpy":
        monkeypatch.setenv("HPE_KERNELS", "numpy")
    elif kernels() is None:
        pytest.skip("_hpe_kernels not built")

    rng = np.random.default_rng(11)
    n = 20_000
    cols = [rng.uniform(-200, 200, n), rng.uniform(-200, 200, n), rng.uniform(-200, 200, n)]
    tol = 1e-4
    edge = np.concatenate(
        [
            np.rad2deg(np.arccos(tol * (1 + np.linspace(-1e-8, 1e-8, 41)))),  # |cos b| around gimbal_tol
            90.0 - np.array([0.0, 1e-12, 1e-9, 1e-6, 0.0057, 0.0058, 0.999999, 1.0, 1.000001]),  # near tol 1 deg
            90.0 - near + np.linspace(-2e-6, 2e-6, 41),  # around this test's near-gimbal tolerance
            90.0 - np.rad2deg(np.arcsin(np.sin(np.deg2rad(near)))) + np.linspace(-2e-6, 2e-6, 41),
            [90.0, -90.0, 180.0, -180.0, 0.0, -0.0, 270.0, -270.0, 1e20, -1e20, 89.99858, 90.00142],
        ]
    )
    edge = np.concatenate([edge, -edge, 180.0 - edge, edge - 180.0])
    screened = 0
    for name in system_names():
        system = get_system(name)
        c = [v.copy() for v in cols]
        k = len(edge)
        for m in range(3):  # put the edge values on every role, so the middle turn gets them whatever it is
            c[m][m * k : (m + 1) * k] = edge
        c[0][-5:] = [np.nan, np.inf, -np.inf, 0.0, 1e300]
        ref = audit_columns(c, system, "angles", near)
        got = audit_columns(c, system, "angles", near, lock_distance=False)
        screened += screen_applies(system)
        for key in CHECKS:
            assert np.array_equal(ref[key], got[key]), (name, key, np.flatnonzero(ref[key] != got[key])[:5])
    assert screened >= 3


def test_screened_matrix_flags_equal_decomposition():
    """Matrices of systems whose primary solutions always meet their ranges are checked without the
    decomposition: the same masks bit for bit (lock rows, near-lock rows, non-rotations, NaN)."""
    from hpe_cli.rotation.audit import audit_columns, matrix_screen_applies
    from hpe_cli.rotation.systems import system_names

    rng = np.random.default_rng(12)
    n = 6000
    tol = 1e-4
    mids = np.concatenate(
        [
            np.rad2deg(np.arccos(tol * (1 + np.linspace(-1e-6, 1e-6, 41)))),
            90.0 - np.array([0.0, 1e-12, 1e-9, 0.0057, 0.0058, 0.999999, 1.0, 1.000001]),
        ]
    )
    screened = 0
    for name in system_names():
        system = get_system(name)
        pyr = np.c_[rng.uniform(-180, 180, n), rng.uniform(-90, 90, n), rng.uniform(-180, 180, n)]
        k = len(mids)
        for m in range(3):
            pyr[m * k : (m + 1) * k, m] = mids
            pyr[3 * k + m * k : 3 * k + (m + 1) * k, m] = -mids
        R = system.from_angles(pyr)
        R[-3] *= 2.0
        R[-2, 0, 0] = np.nan
        R[-1] = R[-1] @ np.diag([1.0, 1, -1])
        cols = [np.ascontiguousarray(R[:, i, j]) for i in range(3) for j in range(3)]
        ref = audit_columns(cols, system, "matrix")
        got = audit_columns(cols, system, "matrix", lock_distance=False, primary=False)
        screened += matrix_screen_applies(system)
        for key in CHECKS:
            assert np.array_equal(ref[key], got[key]), (name, key, np.flatnonzero(ref[key] != got[key])[:5])
    assert screened >= 3
