"""The nine new built-in systems: worked examples rebuilt by hand/SciPy, round trips, improper frames, real data."""

import math

import numpy as np
import pytest
import scipy.io as sio
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import canonical_A
from hpe_cli.rotation import convert_angles, frobenius, get_system, system_names
from hpe_cli.rotation.convert import canonical_to_labels

NEW = ["img2pose", "trinet", "aflw", "openface", "mediapipe", "dad3dheads", "openvino_adas", "synhead", "6drepnet_6d"]
F = np.diag([1.0, -1, -1])
D = np.diag([1.0, -1, 1])
d2r = np.deg2rad


def Rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])  # noqa: E704


def Ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # noqa: E704


def Rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])  # noqa: E704


def img2pose_rotvec(p, y, r):
    """img2pose utils/json_loader_300wlp.py convert_aflw, radians in, as written there (SciPy)."""
    m1 = Rotation.from_euler("xyz", [p, -y, -r], degrees=False).as_matrix()
    return Rotation.from_matrix(np.transpose(m1)).as_rotvec()


# independent stored-matrix formulas: (angles kind?) -> stored matrix from (p, y, r) in degrees
def hand_matrix(name, p, y, r):
    P, Y, R = d2r([p, y, r])
    A = canonical_A([[p, y, r]])[0]
    return {
        "img2pose": Rotation.from_rotvec(img2pose_rotvec(P, Y, R)).as_matrix(),
        "trinet": Rx(P) @ Ry(-Y) @ Rz(R),  # TriNet W300_EulerAngles2Vectors
        "aflw": Ry(-Y) @ Rx(P) @ Rz(-R),  # TriNet AFLW_EulerAngles2RotationMatrix
        "openface": Rx(P) @ Ry(Y) @ Rz(R),  # OpenFace R = Rx Ry Rz (its own angles)
        "mediapipe": A,  # rotation block = A
        "dad3dheads": F @ A,  # diag(1,-1,-1) @ MV[:3,:3], MV block = A
        "openvino_adas": Rz(Y) @ Ry(P) @ Rx(-R),  # model card: Rz(y) Ry(p) Rx(r) with roll clockwise
        "synhead": canonical_A([[p, -y, r]])[0],  # 300W-LP with yaw negated
        "6drepnet_6d": A.T,  # G = get_R(p, y, r) = A.T
    }[name]


def test_new_builtins_present():
    assert set(NEW) <= set(system_names())


@pytest.mark.parametrize("name", NEW)
def test_worked_examples_rebuilt_independently(name):
    s = get_system(name)
    assert s.examples, f"{name} has no worked example"
    for e in s.examples:
        if "angles" in e:
            M = hand_matrix(name, *e["angles"])
        else:  # canonical (300W-LP) angles: the system has no angles of its own
            M = hand_matrix(name, *e["canonical_angles"])
        if "matrix" in e:
            assert np.abs(np.array(e["matrix"]) - M).max() < 2e-9
        if "values" in e:
            v = np.array(e["values"])
            if s.storage_kind == "rotvec":
                assert np.abs(v - img2pose_rotvec(*d2r(e["canonical_angles"]))).max() < 2e-9
            elif s.storage_kind == "matrix":
                assert np.abs(v - M.ravel()).max() < 2e-9
            elif s.storage_kind == "6d":
                assert np.abs(v - np.concatenate([M[:, 0], M[:, 1]])).max() < 2e-9


@pytest.mark.parametrize("name", NEW)
def test_system_matrix_is_hand_formula(name):
    s = get_system(name)
    rng = np.random.default_rng(7)
    pyr = rng.uniform([-170, -89, -170], [170, 89, 170], (50, 3))
    if s.angle_frame == "canonical":
        R = s.from_canonical(canonical_A(pyr))
    else:
        R = s.from_angles(pyr)
    ref = np.stack([hand_matrix(name, *a) for a in pyr])
    assert np.abs(R - ref).max() < 1e-13


def test_improper_frames_by_conjugation():
    """trinet and aflw live in D = diag(1,-1,1): canonical A = D R D, written by hand."""
    rng = np.random.default_rng(3)
    pyr = rng.uniform(-180, 180, (200, 3))
    A = canonical_A(pyr)
    tri = get_system("trinet")
    assert np.abs(tri.from_canonical(A) - D @ A @ D).max() < 1e-14
    assert np.abs(tri.to_canonical(D @ A @ D) - A).max() < 1e-14
    # trinet's angles are the 300W-LP angles
    c = canonical_to_labels(A, "trinet")
    ref = canonical_to_labels(A, "300w_lp")
    assert np.abs(c.primary - ref.primary).max() < 1e-9
    af = get_system("aflw")
    Raflw = af.from_angles(pyr)
    assert np.abs(af.to_canonical(Raflw) - D @ Raflw @ D).max() < 1e-14
    assert all(np.linalg.det(af.to_canonical(Raflw)) > 0.999999)
    assert not tri.proper_frame and "LEFT-HANDED" in tri.describe()["frame"]
    assert get_system("img2pose").proper_frame


def test_aflw_versus_hopenet_reading():
    """Hopenet reads AFLW (p, y, r) as 300W-LP (p, y, -r): equal only for small turns."""
    small = convert_angles([[2.0, 3.0, 1.0]], "aflw", "300w_lp").primary[0]
    assert np.abs(small - [2.0, 3.0, -1.0]).max() < 0.2  # second order: p * y
    big = convert_angles([[30.0, 60.0, 20.0]], "aflw", "300w_lp").primary[0]
    assert np.abs(big - [30.0, 60.0, -20.0]).max() > 5


ALL = list(system_names())
deg = st.floats(-180, 180, allow_nan=False).filter(lambda v: v > -180)
near_lock = st.sampled_from([90.0, -90.0]).flatmap(
    lambda y: st.sampled_from([0.0, 1e-9, 1e-6, 1e-3]).map(lambda d: y - np.sign(y) * d)
)
pyr_any = st.one_of(st.tuples(deg, deg, deg), st.tuples(deg, near_lock, deg))


@given(pyr=pyr_any, data=st.data())
def test_round_trip_every_pair(pyr, data):
    a = data.draw(st.sampled_from(ALL))
    b = data.draw(st.sampled_from(ALL))
    A0 = canonical_A([pyr])
    sa, sb = get_system(a), get_system(b)
    Ra = sa.from_canonical(A0)
    there = canonical_to_labels(sa.to_canonical(Ra), sb)
    back = canonical_to_labels(sb.to_canonical(there.matrix), sa)
    assert frobenius(back.matrix, Ra).max() < 1e-12
    # through the stored values too
    for s, R in ((sa, Ra), (sb, there.matrix)):
        if s.storage_kind != "angles":
            R2, reasons = s.values_to_matrix(s.matrix_to_values(R))
            assert reasons is None and frobenius(R2, R).max() < 1e-12


def test_real_aflw2000_through_new_systems(realdata):
    files = sorted((realdata / "aflw2000_prnet").glob("*.mat"))
    pp = np.array([sio.loadmat(f)["Pose_Para"][0, :3] for f in files], dtype=np.float64)
    A = canonical_A(np.rad2deg(pp))
    for name in NEW:
        c = canonical_to_labels(A, name)
        ref = (
            np.stack([hand_matrix(name, *np.rad2deg(x)) for x in pp])
            if get_system(name).angle_frame == "canonical" or name in ("trinet", "synhead")
            else None
        )
        if name == "trinet":  # TriNet's vectors of Pose_Para (W300 class) are exactly hpe's trinet matrix
            ref = np.stack([Rx(p) @ Ry(-y) @ Rz(r) for p, y, r in pp])
        if name == "synhead":
            ref = None
        if ref is not None:
            assert np.abs(c.matrix - ref).max() < 1e-13, name
        back = canonical_to_labels(get_system(name).to_canonical(c.matrix), "300w_lp")
        assert np.abs(back.primary - np.rad2deg(pp)).max() < 1e-9, name
    # img2pose's rotvec of the real labels equals its own conversion code
    s = get_system("img2pose")
    rv = s.matrix_to_values(canonical_to_labels(A, s).matrix)
    assert np.abs(rv - np.stack([img2pose_rotvec(*x) for x in pp])).max() < 1e-12


def test_real_biwi_and_300wlp_through_camera_frame_systems(realdata):
    """BIWI's pose.txt R is in the depth camera frame (x right, y down, z forward): the same frame as
    openface, img2pose and opencv. Its .bin angles through hpe land on R itself in each of them."""
    bins = sorted((realdata / "biwi" / "db_annotations_subset").rglob("*.bin"))
    pyr = np.array([np.fromfile(b, dtype="<f4")[3:6] for b in bins], dtype=np.float64)
    # BIWI .bin: R = Rz(roll) Ry(yaw) Rx(pitch) (SPEC section 8), written here by hand
    R = np.stack([Rz(d2r(r)) @ Ry(d2r(y)) @ Rx(d2r(p)) for p, y, r in pyr])
    for name in ("openface", "opencv"):
        c = convert_angles(pyr, "biwi", name)
        assert np.abs(c.matrix - R).max() < 1e-12, name
    c = convert_angles(pyr, "biwi", "img2pose")
    rv = get_system("img2pose").matrix_to_values(c.matrix)
    assert np.abs(rv - Rotation.from_matrix(R).as_rotvec()).max() < 1e-12
    # TriNet's BIWI vectors (BIWI_EulerAngles2Vectors: columns of Rz Ry Rx) are the biwi stored matrix
    assert np.abs(get_system("biwi").from_angles(pyr) - R).max() < 1e-12
    # pose.txt of frame 00003 (float text) read as openface's matrix: pose_Rx..Rz are its XYZ angles
    P = np.loadtxt(realdata / "biwi" / "hpdb" / "01" / "frame_00003_pose.txt", max_rows=3)
    Pq = Rotation.from_matrix(P).as_matrix()  # nearest rotation of the 6-digit text
    ang = canonical_to_labels(get_system("openface").to_canonical(Pq[None]), "openface").primary[0]
    assert np.abs(Rotation.from_euler("XYZ", ang, degrees=True).as_matrix() - Pq).max() < 1e-12


def test_real_300wlp_sample(realdata):
    pp = sio.loadmat(realdata / "300wlp_face3d" / "IBUG_image_008_1_0.mat")["Pose_Para"][0, :3].astype(np.float64)
    A = canonical_A(np.rad2deg(pp)[None])
    for name in NEW:
        s = get_system(name)
        R = s.from_canonical(A)
        if s.storage_kind != "angles":
            R2, reasons = s.values_to_matrix(s.matrix_to_values(R))
            assert reasons is None and np.abs(R2 - R).max() < 1e-13
        assert np.abs(canonical_to_labels(s.to_canonical(R), "300w_lp").primary[0] - np.rad2deg(pp)).max() < 1e-9
    tri = get_system("trinet").from_canonical(A)[0]
    p, y, r = pp
    assert np.abs(tri - Rx(p) @ Ry(-y) @ Rz(r)).max() < 1e-14  # TriNet's W300 vectors of this label
