"""BIWI readers and the ``biwi`` rotation system, against the real files (PROVENANCE.md §4).

Oracles: the numbers printed in PROVENANCE.md, SciPy's ``Rotation``, Hopenet's
BIWI formula (re-typed here from its published equations), and physics (which
way the nose turns).
"""

from __future__ import annotations

import shutil
import tarfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hpe_cli.datasets.biwi import (
    nearest_rotation,
    read_biwi,
    read_biwi_tgz,
    read_calibration,
    read_pose_bin,
    read_pose_txt,
)
from hpe_cli.errors import HpeError
from hpe_cli.rotation import convert_angles, convert_matrices, frobenius, get_system

BIWI = Path(__file__).resolve().parents[3] / "shared" / "realdata" / "biwi"
needs_data = pytest.mark.skipif(not BIWI.is_dir(), reason="shared/realdata not available")
F = np.diag([1.0, -1.0, -1.0])

R3 = np.array([[0.997978, 0.0272944, 0.0574071], [-0.0346956, 0.990621, 0.132163], [-0.0532613, -0.133887, 0.989564]])
T3 = np.array([51.9358, 38.2631, 881.756])


def zyx_direct(R):
    """PROVENANCE's direct split: pitch=atan2(r21,r22), yaw=asin(-r20), roll=atan2(r10,r00), degrees."""
    return np.degrees([np.arctan2(R[2, 1], R[2, 2]), np.arcsin(-R[2, 0]), np.arctan2(R[1, 0], R[0, 0])])


def hopenet(R):
    """Hopenet's BIWI reader: transpose, then pitch, -yaw, -roll of a Z-Y-X split (degrees)."""
    R = R.T
    roll = -np.arctan2(R[1, 0], R[0, 0])
    yaw = -np.arctan2(-R[2, 0], np.sqrt(R[2, 1] ** 2 + R[2, 2] ** 2))
    pitch = np.arctan2(R[2, 1], R[2, 2])
    return np.degrees([pitch, yaw, roll])


# ------------------------------------------------------------------ the system
angles = st.tuples(st.floats(-179, 179), st.floats(-89, 89), st.floats(-179, 179))


@settings(max_examples=60, deadline=None)
@given(st.lists(angles, min_size=1, max_size=5))
def test_biwi_system_is_scipy_extrinsic_xyz(rows):
    pyr = np.asarray(rows)
    biwi = get_system("biwi")
    M = biwi.from_angles(pyr)
    np.testing.assert_allclose(M, Rotation.from_euler("xyz", pyr, degrees=True).as_matrix(), atol=1e-12)
    # its canonical matrix is F @ R @ F (SPEC §3's opencv frame)
    np.testing.assert_allclose(biwi.to_canonical(M), F @ M @ F, atol=1e-15)
    # round trip biwi -> 300w_lp -> biwi
    there = convert_angles(pyr, "biwi", "300w_lp")
    back = convert_angles(there.primary, "300w_lp", "biwi")
    assert frobenius(back.canonical, there.canonical).max() < 1e-12
    np.testing.assert_allclose(back.primary, pyr, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.lists(angles, min_size=1, max_size=5))
def test_hopenet_reader_gives_300wlp_angles_of_biwi_matrix(rows):
    M = Rotation.from_euler("xyz", np.asarray(rows), degrees=True).as_matrix()
    conv = convert_matrices(M, "biwi", "300w_lp")
    A = get_system("300w_lp")
    for k in range(len(M)):
        h = hopenet(M[k])
        if conv.gimbal_lock[k]:  # only p + r is defined at the lock: compare the rotations
            np.testing.assert_allclose(A.from_angles([h])[0], conv.matrix[k], atol=1e-9)
        else:
            d = (np.asarray(conv.primary[k]) - np.asarray(h) + 180.0) % 360.0 - 180.0  # 180 and -180 are one angle
            np.testing.assert_allclose(d, 0.0, atol=1e-9)


def test_biwi_signs_are_physical():
    biwi = get_system("biwi")
    nose_model = np.array([0.0, 0.0, -1.0])  # the model's nose points at the camera (-z, camera frame)
    top_model = np.array([0.0, -1.0, 0.0])  # the top of the head is up (-y)
    yaw = biwi.from_angles([[0, 30, 0]])[0] @ nose_model
    pitch = biwi.from_angles([[30, 0, 0]])[0] @ nose_model
    roll = biwi.from_angles([[0, 0, 30]])[0] @ top_model
    assert yaw[0] < -0.4  # positive yaw: nose to the image left, as in 300W-LP
    assert pitch[1] > 0.4  # positive BIWI pitch: nose down (y down), opposite to 300W-LP
    assert roll[0] > 0.4  # positive roll: head top to the image right, as in 300W-LP
    p, y, r = convert_angles([[30, 0, 0], [0, 30, 0], [0, 0, 30]], "biwi", "300w_lp").primary
    np.testing.assert_allclose([p, y, r], [[-30, 0, 0], [0, 30, 0], [0, 0, 30]], atol=1e-12)


def test_nearest_rotation():
    M = R3 + 1e-6
    Q = nearest_rotation(M)
    np.testing.assert_allclose(Q @ Q.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(Q) == pytest.approx(1.0)
    assert np.abs(Q - M).max() < 1e-5


# -------------------------------------------------------------- the real files
@needs_data
def test_pose_txt_frame3():
    R, c = read_pose_txt(BIWI / "hpdb" / "01" / "frame_00003_pose.txt")
    np.testing.assert_allclose(R, R3, atol=2e-6)
    np.testing.assert_allclose(c, T3)
    np.testing.assert_allclose(zyx_direct(R), [-7.71, 3.05, -1.99], atol=0.006)
    np.testing.assert_allclose(hopenet(R), [7.61, 3.29, -1.57], atol=0.006)


@needs_data
def test_table_conventions_on_frame3():
    own = read_biwi(BIWI / "hpdb")
    assert list(own["file"]) == ["01/frame_00003_pose.txt"] and own["sequence"][0] == "01" and own["frame"][0] == 3
    np.testing.assert_allclose(own[["pitch", "yaw", "roll"]].to_numpy()[0], zyx_direct(R3), atol=1e-4)
    np.testing.assert_allclose(own[["center_x", "center_y", "center_z"]].to_numpy()[0], T3)
    w = read_biwi(BIWI / "hpdb", system="300w_lp")
    np.testing.assert_allclose(w[["pitch", "yaw", "roll"]].to_numpy()[0], hopenet(R3), atol=1e-4)
    A = w[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(3, 3)
    np.testing.assert_allclose(A, F @ R3 @ F, atol=2e-6)


@needs_data
def test_bin_agrees_with_pose_txt_of_the_neighbouring_frame():
    """Sequence 01 has no frame 3 .bin; frames 4-10 are the same still pose within ~0.6 deg."""
    bins = read_biwi(BIWI / "db_annotations_subset")
    near = bins[(bins["sequence"] == "01") & (bins["frame"] <= 10)]
    assert list(near["frame"]) == list(range(4, 11))
    b = near[["pitch", "yaw", "roll"]].to_numpy()
    own = zyx_direct(R3)
    assert np.abs(b - own).max() < 1.0
    np.testing.assert_allclose(near[["center_x", "center_y", "center_z"]].to_numpy(), np.tile(T3, (7, 1)), atol=1.0)
    # the other readings of the same matrix disagree with the .bin by far more
    for other in (hopenet(R3), zyx_direct(R3.T), zyx_direct(F @ R3 @ F)):
        assert np.abs(b - other).max() > 5.0
    np.testing.assert_allclose(b[0], [-7.79, 3.60, -2.44], atol=0.006)
    # of the two Tait-Bryan splits of R, Z-Y-X (the biwi system) is the one nearer the .bin
    mean = b.mean(0)
    xyz_intrinsic = Rotation.from_matrix(R3).as_euler("XYZ", degrees=True)
    assert np.linalg.norm(zyx_direct(R3) - mean) < 0.7 < np.linalg.norm(xyz_intrinsic - mean)


@pytest.fixture(scope="module")
def tgz():
    if not BIWI.is_dir():
        pytest.skip("shared/realdata not available")
    return read_biwi_tgz(BIWI / "db_annotations.tgz")


@needs_data
def test_tgz_reader(tgz):
    t = tgz
    assert len(t) == 15677
    assert t["sequence"].nunique() == 24
    assert not ((t["sequence"] == "01") & (t["frame"] == 3)).any()
    first = t.iloc[0]
    assert first["file"] == "01/frame_00004_pose.bin"
    np.testing.assert_allclose(
        first[["center_x", "center_y", "center_z", "pitch", "yaw", "roll"]].to_numpy(float),
        [51.85, 38.57, 881.65, -7.79, 3.60, -2.44],
        atol=0.006,
    )
    for col, lo, hi in (("pitch", -84.35, 53.55), ("yaw", -66.95, 76.89), ("roll", -69.62, 63.37)):
        assert t[col].min() == pytest.approx(lo, abs=0.006) and t[col].max() == pytest.approx(hi, abs=0.006)
    ext = t.set_index("file")
    assert ext.loc["01/frame_00320_pose.bin", "yaw"] == pytest.approx(-66.95, abs=0.006)
    assert ext.loc["06/frame_00208_pose.bin", "pitch"] == pytest.approx(-84.35, abs=0.006)
    # the archive's values are the extracted files' values, bit for bit
    sub = read_biwi(BIWI / "db_annotations_subset").set_index("file")
    cols = ["pitch", "yaw", "roll", "center_x", "center_y", "center_z"]
    np.testing.assert_array_equal(ext.loc[sub.index, cols].to_numpy(), sub[cols].to_numpy())
    raw = read_pose_bin(BIWI / "db_annotations_subset" / "21" / "frame_00134_pose.bin")
    np.testing.assert_array_equal(ext.loc["21/frame_00134_pose.bin", cols].to_numpy(float), raw[[3, 4, 5, 0, 1, 2]])


@needs_data
def test_tgz_in_300wlp_roundtrips(tgz):
    own = tgz[["pitch", "yaw", "roll"]].to_numpy()
    assert tgz["roundtrip_err"].max() < 1e-12 and not tgz["gimbal_lock"].any()
    there = convert_angles(own, "biwi", "300w_lp")
    assert there.roundtrip_err.max() < 1e-12 and not there.gimbal_lock.any()
    # to first order BIWI's yaw keeps its 300W-LP sign and its pitch flips ...
    w = there.primary
    big_y, big_p = np.abs(own[:, 1]) > 10, np.abs(own[:, 0]) > 10
    assert (np.sign(w[big_y, 1]) == np.sign(own[big_y, 1])).mean() > 0.98
    assert (np.sign(w[big_p, 0]) == -np.sign(own[big_p, 0])).mean() > 0.98
    # ... but the split order matters: on real frames the .bin angles are far from 300W-LP's
    assert np.abs(w[:, 1] - own[:, 1]).max() > 40 and np.abs(w[:, 2] - own[:, 2]).max() > 60
    back = convert_angles(there.primary, "300w_lp", "biwi").primary
    np.testing.assert_allclose(back, own, atol=1e-9)


@needs_data
def test_calibration_files():
    rgb = read_calibration(BIWI / "hpdb" / "01" / "rgb.cal")
    np.testing.assert_allclose(rgb["K"], [[517.679, 0, 320], [0, 517.679, 240.5], [0, 0, 1]])
    np.testing.assert_allclose(rgb["t"], [-24.0198, 5.8896, -13.2308])
    assert rgb["size"] == (640, 480) and not rgb["dist"].any()
    assert np.abs(rgb["R"] - np.eye(3)).max() < 0.02
    depth = read_calibration(BIWI / "hpdb" / "01" / "depth.cal")
    assert depth["K"][0, 0] == pytest.approx(575.816)
    np.testing.assert_array_equal(depth["R"], np.eye(3))
    # the head centre of frame 3 projects inside the 640 x 480 depth image, right of and below its centre
    u, v = (depth["K"] @ T3)[:2] / T3[2]
    assert 320 < u < 400 and 240 < v < 300


# ----------------------------------------------------------------------- errors
def test_bad_files(tmp_path):
    seq = tmp_path / "01"
    seq.mkdir()
    short = seq / "frame_00001_pose.bin"
    short.write_bytes(np.zeros(5, "<f4").tobytes())
    with pytest.raises(HpeError, match="frame_00001_pose.bin.*24 bytes"):
        read_pose_bin(short)
    txt = seq / "frame_00001_pose.txt"
    txt.write_text("1 0 0\n0 1 0\n0 0 1\n\n1 2\n")
    with pytest.raises(HpeError, match="frame_00001_pose.txt.*12 numbers"):
        read_pose_txt(txt)
    txt.write_text("1 0 0\n0 1 0\n0 0 -1\n\n1 2 3\n")
    with pytest.raises(HpeError, match="rotation"):
        read_pose_txt(txt)
    txt.write_text("1 0 0\n0 1 0\n0 0 x\n\n1 2 3\n")
    with pytest.raises(HpeError, match="non-number"):
        read_pose_txt(txt)
    with pytest.raises(HpeError, match="no such"):
        read_biwi(tmp_path / "nothing")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(HpeError, match="no BIWI"):
        read_biwi(empty)


@needs_data
def test_truncated_tgz(tmp_path):
    data = (BIWI / "db_annotations.tgz").read_bytes()
    cut = tmp_path / "db_annotations.tgz"
    cut.write_bytes(data[: len(data) // 3])
    with pytest.raises(HpeError, match="db_annotations.tgz"):
        read_biwi_tgz(cut)


@needs_data
def test_small_tgz_and_single_file(tmp_path):
    arc = tmp_path / "a.tgz"
    with tarfile.open(arc, "w:gz") as tf:
        tf.add(BIWI / "db_annotations_subset" / "02" / "frame_00348_pose.bin", arcname="02/frame_00348_pose.bin")
        tf.add(BIWI / "hpdb" / "01" / "rgb.cal", arcname="01/rgb.cal")  # skipped
    t = read_biwi(arc)
    assert list(t["file"]) == ["02/frame_00348_pose.bin"]
    assert t["pitch"][0] == pytest.approx(53.547, abs=1e-3)
    one = tmp_path / "03"
    one.mkdir()
    shutil.copy(BIWI / "db_annotations_subset" / "03" / "frame_00562_pose.bin", one)
    t = read_biwi(one / "frame_00562_pose.bin")
    assert t["sequence"][0] == "03" and t["frame"][0] == 562 and t["yaw"][0] == pytest.approx(76.893, abs=1e-3)


def test_tgz_member_size_checked_before_reading(tmp_path, monkeypatch):
    """A huge pose member is refused from its tar header; its data is never read."""
    import io
    import tarfile

    import hpe_cli.datasets.biwi as biwi_mod
    from hpe_cli.errors import HpeError

    path = tmp_path / "db_annotations.tgz"
    with tarfile.open(path, "w:gz") as tf:
        info = tarfile.TarInfo("01/frame_00003_pose.bin")
        info.size = 4 << 20
        tf.addfile(info, io.BytesIO(b"\0" * info.size))
    calls = []
    real = tarfile.TarFile.extractfile
    monkeypatch.setattr(tarfile.TarFile, "extractfile", lambda self, m: calls.append(m) or real(self, m))
    with pytest.raises(HpeError, match=r"01/frame_00003_pose.bin: expected 24 bytes \(6 float32\), got 4194304"):
        biwi_mod.read_biwi_tgz(path)
    assert not calls


# ------------------------------------------------------------- rejected frames
@needs_data
def test_bad_frames_collected_not_raised(tmp_path):
    """With ``bad=[]`` a damaged pose file is one reject (its reason, its file) and the other frames read as before."""
    hp = tmp_path / "hpdb" / "01"
    hp.mkdir(parents=True)
    shutil.copy(BIWI / "hpdb" / "01" / "frame_00003_pose.txt", hp)
    (hp / "frame_00004_pose.txt").write_text("1 0 0\n0 1 0\n0 0 -1\n\n1 2 3\n")  # a reflection
    (hp / "frame_00005_pose.txt").write_bytes(b"\xff\xfe")  # not ASCII
    with pytest.raises(HpeError, match="frame_00004_pose.txt: expected a rotation"):
        read_biwi(tmp_path / "hpdb")
    bad = []
    t = read_biwi(tmp_path / "hpdb", bad=bad)
    assert list(t["file"]) == ["01/frame_00003_pose.txt"]
    np.testing.assert_allclose(
        t[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(3, 3), nearest_rotation(R3), atol=1e-12
    )
    assert [b["file"] for b in bad] == ["01/frame_00004_pose.txt", "01/frame_00005_pose.txt"]
    assert bad[0]["reason"].startswith("expected a rotation matrix") and bad[0]["frame"] == 4
    assert bad[0]["message"] == f"{hp / 'frame_00004_pose.txt'}: {bad[0]['reason']}"
    assert bad[1]["reason"] == "cannot read BIWI pose file (UnicodeDecodeError)"
    only_bad = tmp_path / "only" / "01"
    only_bad.mkdir(parents=True)
    shutil.copy(hp / "frame_00004_pose.txt", only_bad)
    with pytest.raises(HpeError, match=r"no readable BIWI pose file in .*only \(1 rejected\)"):
        read_biwi(tmp_path / "only", bad=[])


def test_tgz_bad_member_collected_unread(tmp_path, monkeypatch):
    """In an archive, a pose member of the wrong size is a reject, still judged from its header alone."""
    import io

    path = tmp_path / "db_annotations.tgz"
    good = np.array([51.9, 38.3, 881.8, -7.7, 3.4, -2.5], "<f4").tobytes()
    with tarfile.open(path, "w:gz") as tf:
        for name, data in (("01/frame_00003_pose.bin", b"\0" * (4 << 20)), ("01/frame_00004_pose.bin", good)):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
    calls = []
    real = tarfile.TarFile.extractfile
    monkeypatch.setattr(tarfile.TarFile, "extractfile", lambda self, m: calls.append(m.name) or real(self, m))
    bad = []
    t = read_biwi_tgz(path, bad=bad)
    assert list(t["file"]) == ["01/frame_00004_pose.bin"] and calls == ["01/frame_00004_pose.bin"]
    assert [(b["file"], b["frame"], b["reason"]) for b in bad] == [
        ("01/frame_00003_pose.bin", 3, "expected 24 bytes (6 float32), got 4194304")
    ]
