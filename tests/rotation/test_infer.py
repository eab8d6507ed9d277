"""The system search of hpe_cli.rotation.infer against SciPy, SPEC §2-3 formulas and the real AFLW2000 files."""

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import canonical_A
from hpe_cli.geometry.template import fit_template, reference_template, to_canonical_points
from hpe_cli.rotation import infer as inf
from hpe_cli.rotation import load_system
from hpe_cli.rotation.distances import geodesic_deg

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "conventions"
sys.path.insert(0, str(FIXTURES))

import lp300w  # noqa: E402
import made_up  # noqa: E402
import scipy_style  # noqa: E402
import sixdrepnet  # noqa: E402
import synergynet  # noqa: E402
import tddfa_v2  # noqa: E402

PYR = ("pitch", "yaw", "roll")


def builder(func, roles="pitch,yaw,roll", units="radians", **kw):
    roles = roles.split(",")
    return inf.infer_builder(inf.as_builder(func, roles, units), roles=roles, units=units, **kw)


def decoder(func, roles="yaw,pitch,roll", units="radians", **kw):
    roles = roles.split(",")
    return inf.infer_decoder(inf.as_decoder(func, roles, units), roles=roles, units=units, **kw)


def fresh_angles(n=200, seed=11):
    return np.random.default_rng(seed).uniform(-180, 180, (n, 3))


# ----------------------------------------------------------------------------- the candidate space
def test_576_distinct_functions():
    cm = inf.candidate_matrices(inf.spread_angles(8, seed=3))
    flat = cm.reshape(len(cm), -1)
    d = np.abs(flat[:, None, :] - flat[None, :, :]).max(-1)
    np.fill_diagonal(d, np.inf)
    assert len(cm) == 576 and d.min() > 1e-3


@pytest.mark.parametrize("k", [0, 100, 350, 575])
def test_candidate_matrices_match_scipy(k):
    c = inf.candidates()[k]
    pyr = fresh_angles(10)
    ang = np.stack([pyr[:, PYR.index(r)] * (1 if h == "right" else -1) for r, h in zip(c.roles, c.hands)], -1)
    ref = Rotation.from_euler(c.axes.upper(), ang, degrees=True).as_matrix()
    assert np.abs(inf.candidate_matrices(pyr, k)[0] - ref).max() < 1e-12


def test_spread_angles_cover_every_role():
    a = inf.spread_angles(64, seed=0)
    assert a.shape == (64, 3) and (a > -180).all() and (a < 180).all()
    for k in range(3):  # one value per 1/64 bin of the circle
        assert len(np.unique(np.floor((a[:, k] + 180) / 360 * 64))) == 64


def test_random_rotations_are_rotations():
    R = inf.random_rotations(100, seed=2)
    assert np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() < 1e-12
    assert np.abs(np.linalg.det(R) - 1).max() < 1e-12


# ----------------------------------------------------------------------------- the five cases
def test_6drepnet_get_R():
    rep = builder(sixdrepnet.get_R)
    assert rep["fit"] == "exact" and rep["best"] == "6drepnet"
    assert rep["max_error"] < 1e-12
    assert set(rep["matched"]["transpose_of"]) >= {"300w_lp"}  # G = A.T (SPEC §3)


def test_300wlp_builder_and_vectorised_call():
    b = inf.as_builder(lp300w.pose_matrix, PYR, "radians")
    rep = inf.infer_builder(b, roles=PYR, units="radians")
    assert b.state["vectorised"] is True
    assert rep["best"] == "300w_lp"  # not whenet: same function, but pitch,yaw,roll is 300w_lp's order
    assert "whenet" in rep["matched"]["builtins"]


def test_scipy_zyx_builder():
    rep = builder(scipy_style.euler_zyx, "yaw,pitch,roll", "degrees")
    assert rep["fit"] == "exact" and rep["best"] == "scipy_zyx"
    assert rep["_system"].units == "degrees"


def test_3ddfa_v2_decoder_spec_anchors():
    # SPEC §3: on A(2, 3, 1) matrix2angle prints yaw 3.03, pitch -1.95, roll -0.90;
    # on A(20, -50, 15) it prints -37.36, -40.54, -38.64
    for pyr, want in [((2, 3, 1), (3.03, -1.95, -0.90)), ((20, -50, 15), (-37.36, -40.54, -38.64))]:
        got = np.rad2deg(tddfa_v2.matrix2angle(canonical_A([pyr])[0]))
        assert np.abs(got - want).max() < 0.006


def test_3ddfa_v2_decoder_is_found_despite_its_gimbal_branch():
    R = inf.random_rotations(200, seed=5)
    # add rotations inside matrix2angle's |R[2,0]| > 0.998 branch, where it forces roll to 0
    near = Rotation.from_euler(
        "ZYX", np.c_[np.linspace(-170, 170, 8), np.r_[[87.5] * 4, [-88.0] * 4], np.linspace(-60, 60, 8)], degrees=True
    ).as_matrix()
    rep = decoder(tddfa_v2.matrix2angle, rotations=np.concatenate([R, near]))
    assert rep["fit"] == "exact" and rep["best"] == "3ddfa_v2"
    assert rep["near_lock"]["count"] >= 6 and rep["near_lock"]["max_error"] > 1e-3
    assert rep["selection"]["rule"] == "tait_bryan"


def test_made_up_convention_round_trips(tmp_path):
    rep = builder(made_up.made_up, "roll,pitch,yaw", "degrees", name="made_up")
    assert rep["fit"] == "exact" and rep["best"] == "custom"
    path = tmp_path / "made_up.toml"
    path.write_text(rep["_system"].to_toml())
    system = load_system(path)
    pyr = fresh_angles()
    # independent oracle: SciPy's intrinsic Z-X-Z with the fixture's signs
    ref = Rotation.from_euler("ZXZ", np.c_[pyr[:, 2], -pyr[:, 0], pyr[:, 1]], degrees=True).as_matrix()
    assert np.abs(system.from_angles(pyr) - ref).max() < 1e-9
    assert system.selection == "proper" and system.order == ("roll", "pitch", "yaw")
    p1, p2, _, _ = system.to_angles(ref)
    assert np.abs(system.from_angles(p1) - ref).max() < 1e-9
    assert np.abs(system.from_angles(p2) - ref).max() < 1e-9


# ----------------------------------------------------------------------------- no exact fit
def test_synergynet_spec_anchor():
    yaw, pitch, roll = np.rad2deg(synergynet.matrix2angle_corr(canonical_A([(20, -50, 15)])[0]))
    assert abs(yaw - -37.36) < 0.01 and abs(pitch - 20) < 1e-9 and abs(roll - 15) < 1e-9


def test_synergynet_has_no_exact_fit():
    rep = decoder(synergynet.matrix2angle_corr)
    assert rep["fit"] == "none" and rep["best"] == "none" and "_system" not in rep
    part = rep["best_partial"]
    assert "300w_lp" in part["builtins"] and part["explained"] < 0.1 * rep["samples"]
    probes = {tuple(p["nonzero"]): p for p in part["breaks"]["probes"]}
    for one in PYR:  # right when a single angle is non-zero
        assert probes[(one,)]["exact"]
    for two in [("pitch", "yaw"), ("pitch", "roll"), ("yaw", "roll"), PYR]:  # wrong otherwise, and only in yaw
        assert not probes[two]["exact"] and probes[two]["wrong_angles"] == ["yaw"]


def test_builder_with_no_fit_reports_where_it_breaks():
    def bent(p, y, r):  # 300W-LP, but the roll turn is applied twice: not an Euler product
        return lp300w.pose_matrix(p, y, r) @ Rotation.from_euler("z", r).as_matrix()

    rep = builder(bent)
    assert rep["fit"] == "none"
    probes = {tuple(p["nonzero"]): p["exact"] for p in rep["best_partial"]["breaks"]["probes"]}
    assert probes[("pitch",)] and probes[("yaw",)] and probes[("pitch", "yaw")]
    assert not probes[("roll",)]


# ----------------------------------------------------------------------------- any convention
sequences = st.sampled_from(inf.SEQUENCES)
perms = st.permutations(PYR)
hands = st.tuples(*[st.sampled_from([1.0, -1.0])] * 3)


@settings(max_examples=25)
@given(sequences, perms, hands, st.booleans(), st.booleans())
def test_any_scipy_convention_is_recovered(seq, roles, signs, extrinsic, transpose):
    def build(pitch, yaw, roll):
        by = dict(zip(PYR, (pitch, yaw, roll)))
        ang = np.stack([s * np.asarray(by[r]) for r, s in zip(roles, signs)], -1)
        m = Rotation.from_euler(seq if extrinsic else seq.upper(), ang).as_matrix()
        return np.swapaxes(m, -1, -2) if transpose else m

    rep = builder(build)
    assert rep["fit"] == "exact" and rep["max_error"] < 1e-12
    pyr = fresh_angles(50, seed=4)
    want = build(*np.deg2rad(pyr).T)
    assert np.abs(rep["_system"].from_angles(pyr) - want).max() < 1e-9


def test_packed_and_3x3xN_outputs():
    def packed(angles):  # face3d style: one sequence [pitch, yaw, roll]
        return lp300w.pose_matrix(angles[0], angles[1], angles[2])

    b = inf.as_builder(packed, PYR, "radians", packed=True)
    assert inf.infer_builder(b, roles=PYR)["best"] == "300w_lp"

    def lazy(p, y, r):  # rows built from arrays: shape (3, 3, N)
        m = lp300w.pose_matrix(p, y, r)
        return np.moveaxis(m, (-2, -1), (0, 1)) if np.ndim(p) else m

    b = inf.as_builder(lazy, PYR, "radians")
    assert inf.infer_builder(b, roles=PYR)["best"] == "300w_lp" and b.state["vectorised"]


def test_builder_errors():
    with pytest.raises(inf.CallError, match="not orthonormal"):
        builder(lambda p, y, r: 2 * np.eye(3))
    with pytest.raises(inf.CallError, match="raised RuntimeError"):
        builder(lambda p, y, r: (_ for _ in ()).throw(RuntimeError("boom")))


# ----------------------------------------------------------------------------- tables
def test_table_with_float32_matrices_and_decoded_lock_rows():
    rng = np.random.default_rng(8)
    pyr = np.c_[rng.uniform(-180, 180, 300), rng.uniform(-90, 90, 300), rng.uniform(-180, 180, 300)]
    pyr[:3, 1] = [89.99, -89.995, 89.9999]
    R = canonical_A(pyr).astype(np.float32)
    pyr[:3, 0] += 7.0  # labels near the lock split p and r badly: only the sum is observable there
    rep = inf.infer_table(pyr, R)
    assert rep["fit"] == "exact" and rep["best"] == "300w_lp" and rep["matched"]["excused_near_lock"] == 3
    far = np.flatnonzero(np.abs(pyr[:, 1]) < 60)[0]
    pyr[far, 0] += 7.0  # the same error away from the lock is not excused
    assert inf.infer_table(pyr, R)["fit"] == "none"


def test_table_many_rows_checks_leaders_on_every_row():
    pyr = fresh_angles(3000, seed=9)
    R = Rotation.from_euler("ZYX", pyr[:, [1, 0, 2]], degrees=True).as_matrix()
    rep = inf.infer_table(pyr, R)
    assert rep["best"] == "scipy_zyx" and rep["samples"] == 3000
    R[2999] = R[0]  # one bad row outside the searched subset must still be found
    assert inf.infer_table(pyr, R)["fit"] == "none"


# ----------------------------------------------------------------------------- landmarks
def test_reference_template_frame_is_canonical():
    t = reference_template()
    assert t[0, 0] < 0 < t[16, 0]  # point 0 (subject's right jaw) on the image left
    assert t[8, 1] < t[27, 1] < t[19, 1]  # chin below the nose bridge below the brows: y up
    assert t[30, 2] > t[0, 2] and t[30, 2] > t[16, 2]  # nose tip towards the camera: z out of the face


def test_landmarks_synthetic_faces():
    rng = np.random.default_rng(1)
    pyr = np.c_[rng.uniform(-40, 40, 60), rng.uniform(-80, 80, 60), rng.uniform(-30, 30, 60)]
    A = canonical_A(pyr)
    pts = 100 * np.einsum("nij,pj->npi", A, reference_template()) + rng.normal(0, 1.0, (60, 68, 3))
    img = to_canonical_points(pts, "image")  # the same points as an image-y-down table would hold them
    fit = fit_template(to_canonical_points(img, "image"))
    assert np.median(geodesic_deg(fit["R"], A)) < 2
    rep = inf.infer_landmarks(pyr, fit["R"])
    assert rep["best"] == "300w_lp" and rep["fit"] == "clear" and rep["rms_residual_deg"] < 2
    # the same faces labelled as the transpose: the winner is the 6DRepNet matrix read as active
    rep = inf.infer_landmarks(pyr, np.swapaxes(A, 1, 2))
    assert rep["best"] == "custom" and "6drepnet" in rep["matched"]["stored_matrix_of"]


def test_landmarks_real_aflw2000(realdata):
    from hpe_cli.datasets.mat import read_mat_dir

    df = read_mat_dir(realdata / "aflw2000_prnet", landmarks=True)
    P = df[[f"lm3d{i}_{a}" for i in range(68) for a in "xyz"]].to_numpy().reshape(-1, 68, 3)
    fit = fit_template(to_canonical_points(P, "image"))
    rep = inf.infer_landmarks(df[["pitch", "yaw", "roll"]].to_numpy(), fit["R"], row_ids=df["file"].tolist())
    assert rep["best"] == "300w_lp" and rep["fit"] == "clear"
    by = {r: h["rms_residual_deg"] for h in rep["hypotheses"] for r in h["readings"]}
    assert by["300w_lp"] < 3
    assert by["6drepnet (stored matrix read as active)"] > 10 * by["300w_lp"]  # its transpose
    assert by["3ddfa_v2"] > 10 * by["300w_lp"]
    assert len(rep["per_face"]) == 16 and max(f["residual_deg"] for f in rep["per_face"]) < 5


def test_decoder_selection_is_read_from_its_outputs():
    from hpe_cli.rotation import get_system

    # 6DRepNet's matrix, decoded keeping the solution with |pitch| < 90 and |roll| < 90 (SciPy as the oracle)
    def dec(G):
        a = Rotation.from_matrix(G).as_euler("ZYX")  # (roll, yaw, pitch) with |yaw| <= 90
        b = np.array([a[0] + np.pi, np.pi - a[1], a[2] + np.pi])
        b = (b + np.pi) % (2 * np.pi) - np.pi

        def ok(e):
            return abs(e[2]) < np.pi / 2 and abs(e[0]) < np.pi / 2

        r, y, p = b if (not ok(a) and ok(b)) else a
        return p, y, r

    rep = decoder(dec, "pitch,yaw,roll")
    assert rep["best"] == "6drepnet" and rep["selection"]["rule"] == "whenet"
    assert rep["_system"].selection == "whenet" and "keeps the whenet solution" in rep["selection_differs"]
    assert get_system("6drepnet").selection == "tait_bryan"


def test_table_skips_non_rotations():
    pyr = fresh_angles(50)
    R = canonical_A(pyr)
    R[3] *= 2
    R[4, 0, 0] = np.nan
    rep = inf.infer_table(pyr, R)
    assert rep["best"] == "300w_lp" and rep["rows_skipped"] == {"non_finite": 1, "not_a_rotation": 1}


def test_trinet_and_img2pose_functions_are_named():
    from hpe_cli.rotation import rx, ry, rz

    rep = inf.infer_builder(inf.as_builder(lambda p, y, r: rx(p) @ ry(-y) @ rz(r)))  # TriNet W300 vectors
    assert rep["best"] == "trinet"
    rep = inf.infer_builder(inf.as_builder(lambda p, y, r: rx(-p) @ ry(y) @ rz(r)))  # F A F
    assert rep["best"] == "opencv" and "img2pose" in rep["reproduced_by"]
