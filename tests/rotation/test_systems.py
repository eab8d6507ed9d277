"""Built-in systems against SPEC §2-3 relations, the worked examples and SciPy (24 conventions)."""

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import canonical_A
from hpe_cli.rotation import (
    SystemError_,
    canonical_to_labels,
    convert_angles,
    frobenius,
    get_system,
    rx,
    ry,
    rz,
    system_from_dict,
    system_names,
)
from hpe_cli.rotation.distances import angle_diff_deg, geodesic_deg

BUILTINS = ["300w_lp", "whenet", "6drepnet", "3ddfa_v2", "scipy_zyx", "opencv"]
T = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)
F = np.diag([1.0, -1, -1])

deg = st.floats(-180, 180, allow_nan=False).filter(lambda v: v > -180)
near_lock = st.sampled_from([90.0, -90.0]).flatmap(
    lambda y: st.sampled_from([0.0, 1e-9, 1e-6, 1e-3, 0.5]).map(lambda d: y - np.sign(y) * d)
)
pyr_full = st.tuples(deg, deg, deg)
pyr_lock = st.tuples(deg, near_lock, deg)
pyr_any = st.one_of(pyr_full, pyr_lock)


def A_of(pyr):
    return get_system("300w_lp").from_angles(np.atleast_2d(pyr))


def test_builtin_names():
    assert set(BUILTINS) <= set(system_names())


@given(pyr_any)
def test_300wlp_matrix_is_spec_formula(pyr):
    assert np.abs(A_of(pyr) - canonical_A([pyr])).max() < 1e-14


@given(pyr_any)
def test_300wlp_is_left_handed_xyz(pyr):
    p, y, r = np.deg2rad(pyr)
    assert np.abs(A_of(pyr)[0] - rx(p).T @ ry(y).T @ rz(r).T).max() < 1e-14


@pytest.mark.parametrize("name", BUILTINS)
@given(pyr=pyr_any)
def test_both_solutions_rebuild(name, pyr):
    s = get_system(name)
    R = s.from_angles(np.atleast_2d(pyr))
    p1, p2, _, _ = s.to_angles(R)
    assert frobenius(s.from_angles(p1), R).max() < 1e-11
    assert frobenius(s.from_angles(p2), R).max() < 1e-11
    assert ((p1 > -180) & (p1 <= 180)).all() and ((p2 > -180) & (p2 <= 180)).all()


@pytest.mark.parametrize("a,b", list(itertools.permutations(BUILTINS, 2)))
@given(pyr=pyr_any)
def test_a_to_b_to_a_exact(a, b, pyr):
    there = convert_angles(np.atleast_2d(pyr), a, b)
    back = convert_angles(there.primary, b, a)
    R0 = get_system(a).from_angles(np.atleast_2d(pyr))
    # a few machine epsilons away from the lock; the split near it costs <= 1e-11
    assert frobenius(get_system(a).from_angles(back.primary), R0).max() < 1e-11
    assert there.roundtrip_err.max() < 1e-11


@given(pyr_full)
def test_relations_spec_section3(pyr):
    A = A_of(pyr)[0]
    assert np.abs(get_system("6drepnet").from_canonical(A) - A.T).max() < 1e-14
    assert np.abs(get_system("scipy_zyx").from_canonical(A) - T @ A @ T.T).max() < 1e-14
    assert np.abs(get_system("opencv").from_canonical(A) - F @ A @ F).max() < 1e-14
    # 6DRepNet's get_R(p, y, r) = Rz(r) Ry(y) Rx(p) gives A.T with the *same* angles
    p, y, r = np.deg2rad(pyr)
    assert np.abs(get_system("6drepnet").from_angles(np.atleast_2d(pyr))[0] - rz(r) @ ry(y) @ rx(p)).max() < 1e-14
    # opencv angles are the 300W-LP angles
    assert np.abs(get_system("opencv").from_angles(np.atleast_2d(pyr))[0] - F @ A @ F).max() < 1e-14


@given(pyr_full)
def test_3ddfa_v2_split(pyr):
    # 3DDFA_V2 reads A as Rz(roll) @ Ry_left(yaw) @ Rx(pitch); decode it as matrix2angle does
    A = A_of(pyr)[0]
    c = canonical_to_labels(A[None], "3ddfa_v2")
    p, y, r = np.deg2rad(c.primary[0])
    assert np.abs(rz(r) @ ry(-y) @ rx(p) - A).max() < 1e-12
    if abs(A[2, 0]) < 0.998:  # matrix2angle's non-gimbal branch
        yaw, pitch, roll = np.arcsin(A[2, 0]), np.arctan2(A[2, 1], A[2, 2]), np.arctan2(A[1, 0], A[0, 0])
        assert angle_diff_deg(np.rad2deg([pitch, yaw, roll]), c.primary[0]).max() < 1e-9


@given(pyr_full)
def test_scipy_zyx_is_scipy(pyr):
    A = A_of(pyr)[0]
    c = canonical_to_labels(A[None], "scipy_zyx")
    ypr = Rotation.from_matrix(T @ A @ T.T).as_euler("ZYX", degrees=True)
    assert np.abs(Rotation.from_euler("ZYX", ypr, degrees=True).as_matrix() - c.matrix[0]).max() < 1e-12
    if abs(ypr[1]) < 89.9:
        assert angle_diff_deg(c.primary[0], ypr[[1, 0, 2]]).max() < 1e-9


def test_worked_examples():
    c = convert_angles([[20, -50, 15]], "300w_lp", "scipy_zyx")
    assert np.allclose(c.primary[0][[1, 0, 2]], [51.744, -12.700, -30.579], atol=1e-3)
    c = convert_angles([[20, -50, 15], [2, 3, 1]], "300w_lp", "3ddfa_v2")
    ypr = c.primary[:, [1, 0, 2]]
    assert np.allclose(ypr, [[-37.36, -40.54, -38.64], [3.03, -1.95, -0.90]], atol=0.006)
    # image rotation example of SPEC §5: Rz(30) @ A
    c = canonical_to_labels(rz(np.deg2rad(30)) @ A_of([20, -50, 15]), "300w_lp")
    assert np.allclose(c.primary[0], [43.511, -33.607, -19.343], atol=1e-3)


def test_helen_label_is_locked():
    helen = [[-16.0909, -89.99858, -6.8545]]
    c = convert_angles(helen, "300w_lp", "300w_lp")
    assert c.gimbal_lock[0]
    assert abs(1 - abs(c.matrix[0, 0, 2]) - 3.07e-10) < 1e-11
    assert c.roundtrip_err[0] < 1e-12
    assert np.isclose(c.primary[0, 0] + c.primary[0, 2], -22.9454, atol=1e-4)
    assert not convert_angles([[10, 89.5, 5]], "300w_lp", "300w_lp").gimbal_lock[0]


def test_whenet_selection():
    s = get_system("whenet")
    # full-range yaw: a face seen from behind (yaw 150) stays yaw 150 with small pitch and roll
    c = convert_angles([[10, 150, -20], [30, -170, 40]], "300w_lp", "whenet")
    assert np.allclose(c.primary, [[10, 150, -20], [30, -170, 40]])
    assert (np.abs(c.primary[:, [0, 2]]) < 90).all()
    # the same rotation in 300w_lp has |yaw| <= 90
    c2 = convert_angles([[10, 150, -20]], "whenet", "300w_lp")
    assert abs(c2.primary[0, 1]) <= 90 and np.allclose(c2.primary[0], [-170, 30, 160])
    # a rotation WHENet cannot label (|pitch| < 90 in one solution, |roll| < 90 in the other)
    c3 = convert_angles([[100, 10, 20]], "300w_lp", "whenet")
    assert not s.in_range(c3.primary)[0]


@pytest.mark.parametrize("seq", ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx", "xyx", "xzx", "yxy", "yzy", "zxz", "zyz"])
@pytest.mark.parametrize("extrinsic", [False, True])
def test_generic_systems_match_scipy_24(seq, extrinsic):
    """A user-declared right-handed system for each of SciPy's 24 conventions."""
    roles = ["yaw", "pitch", "roll"]
    s = system_from_dict(
        {
            "name": f"g_{seq}_{extrinsic}",
            "sequence": "extrinsic" if extrinsic else "intrinsic",
            "turns": [{"angle": r, "axis": a, "hand": "right"} for r, a in zip(roles, seq)],
        }
    )
    rng = np.random.default_rng(3)
    ang = rng.uniform(-180, 180, (400, 3))  # in turn order
    sp_seq = seq if extrinsic else seq.upper()
    ref = Rotation.from_euler(sp_seq, ang, degrees=True).as_matrix()
    pyr = ang[:, [1, 0, 2]]  # turns carry (yaw, pitch, roll) -> role order
    assert np.abs(s.from_angles(pyr) - ref).max() < 1e-12
    p1, p2, _, _ = s.to_angles(ref)
    ref_ang = Rotation.from_matrix(ref).as_euler(sp_seq, degrees=True)
    assert np.abs(s.from_angles(p1) - ref).max() < 1e-12 and np.abs(s.from_angles(p2) - ref).max() < 1e-12
    assert angle_diff_deg(p1, ref_ang[:, [1, 0, 2]]).max() < 1e-8


def test_toml_roundtrip(tmp_path):
    for name in BUILTINS:
        s = get_system(name)
        f = tmp_path / f"{name}.toml"
        f.write_text(s.to_toml())
        s2 = get_system(str(f))
        assert s2.to_dict() == s.to_dict()


def test_bad_system_files(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('name = "x"\n[[turns]]\nangle = "pitch"\naxis = "q"\n')
    with pytest.raises(SystemError_, match="bad.toml"):
        get_system(str(f))
    f.write_text("name = [")
    with pytest.raises(SystemError_, match="not valid TOML"):
        get_system(str(f))
    with pytest.raises(SystemError_, match="expected a system name"):
        get_system("no_such_system")
    f.write_text(
        'name="r"\nframe=[[1,0,0],[0,1,0],[0,0,-1]]\n'
        + "".join(f'[[turns]]\nangle="{r}"\naxis="{a}"\n' for r, a in zip(["pitch", "yaw", "roll"], "xyz"))
    )
    s = get_system(str(f))  # improper frames are allowed: B A B^T is still a rotation
    assert not s.proper_frame and "LEFT-HANDED" in s.describe()["frame"]
    f.write_text(
        'name="r"\nframe=[[1,0,0],[0,1,0],[0,0,2]]\n'
        + "".join(f'[[turns]]\nangle="{r}"\naxis="{a}"\n' for r, a in zip(["pitch", "yaw", "roll"], "xyz"))
    )
    with pytest.raises(SystemError_, match="frame: expected an orthonormal"):
        get_system(str(f))


def test_geodesic_matches_scipy():
    R1 = Rotation.random(500, random_state=1)
    R2 = Rotation.random(500, random_state=2)
    ref = np.rad2deg((R1.inv() * R2).magnitude())
    assert np.abs(geodesic_deg(R1.as_matrix(), R2.as_matrix()) - ref).max() < 1e-9
    tiny = Rotation.from_rotvec([1e-9, 0, 0]).as_matrix()
    assert np.isclose(geodesic_deg(np.eye(3), tiny), np.rad2deg(1e-9), rtol=1e-6)


def test_describe_in_words():
    d = get_system("scipy_zyx").describe()
    assert "out of the face" in d["frame"].split(";")[0]
    assert set(d) >= {"frame", "axes", "range", "order"}


def test_every_builtin_round_trips_through_its_dict_and_json():
    """A system written into a file's metadata (to_dict/to_json) reads back as the same system."""
    import json

    from hpe_cli.rotation.systems import builtin_systems, system_from_dict

    for name, s in builtin_systems().items():
        for d in (s.to_dict(), json.loads(s.to_json())):
            t = system_from_dict(d, f"<{name}>")
            assert t.name == s.name and t.definition() == s.definition(), name


def test_canonical_system_is_300w_lp_and_the_identity_frame():
    """hpe's canonical frame is 300W-LP's active matrix: ``to_canonical``/``from_canonical`` are the identity on
    SciPy's random rotations; one cached object, the built-in itself."""
    from hpe_cli.rotation.systems import canonical_system

    s = canonical_system()
    assert s is canonical_system() and s is get_system("300w_lp")
    R = Rotation.random(200, random_state=7).as_matrix()
    assert np.allclose(s.to_canonical(R), R, atol=1e-12)
    assert np.allclose(s.from_canonical(R), R, atol=1e-12)
