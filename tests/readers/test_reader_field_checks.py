"""Every reader checks its fields at the door (issue 23, items 1-3): the cases of the issue, one by one.

Oracles: the real files (``tests/data/agora``, ``sample_data``, ``../shared/realdata``) are accepted
unchanged; each damaged copy ends in one line naming the file, the record and the field (exit 1), or in
a reject whose reason names the field -- never a traceback, an ``internal error`` or a silent acceptance.
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import tarfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io

from conftest import hpe, sample_data_script
from hpe_cli.datasets import biwi
from hpe_cli.datasets import panoptic as pan
from hpe_cli.datasets.fields import MAX_TANGENTIAL, distortion_problem, distortion_problems
from hpe_cli.datasets.panoptic_video import VideoFrames
from hpe_cli.errors import HpeError

ROOT = Path(__file__).resolve().parents[2]
AGORA_PKL = ROOT / "tests" / "data" / "agora" / "validation_0_withjv.pkl"
AFLW = ROOT / "sample_data" / "aflw2000"
SYNTH = ROOT / "sample_data" / "panoptic_synth"
REAL = ROOT.parent / "shared" / "realdata"
needs_real = pytest.mark.skipif(not (REAL / "biwi").is_dir(), reason="../shared/realdata is not available")


def one_error(res, *must):
    """Exit 1, one ``Error:`` line containing every string of ``must``, no traceback; returns the line."""
    out = res.output
    assert res.exit_code == 1, out
    assert "Traceback" not in out and "internal error" not in out, out
    errors = [line for line in out.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1, out
    for m in must:
        assert str(m) in errors[0], (m, errors[0])
    return errors[0]


# ================================================================== AGORA
def agora_copy(tmp_path, edit, name="bad_withjv.pkl"):
    df = pd.read_pickle(AGORA_PKL)
    edit(df)
    path = tmp_path / name
    df.to_pickle(path, protocol=4)
    return path


def set_person(col, row, person, value):
    def edit(df):
        cell = list(df.at[row, col])
        cell[person] = value
        df.at[row, col] = cell

    return edit


@pytest.mark.parametrize(
    "edit, message",
    [
        (set_person("cam_j3d", 1, 0, "abc"), "row 1, person 0: cam_j3d: expected a (J, 3) array of numbers"),
        (set_person("cam_j3d", 2, 3, np.full((127, 3), "x")), "row 2, person 3: cam_j3d: expected a (J, 3) array"),
        (
            set_person("occlusion", 1, 2, "abc"),
            "row 1, person 2: occlusion: expected a percentage (a number 0-100), got str 'abc'",
        ),
        (set_person("isValid", 0, 1, "no"), "row 0, person 1: isValid: expected True or False, got str 'no'"),
        (set_person("camR", 1, 0, [[1, 0], [0, 1, 0]]), "row 1, person 0: camR: expected a (3, 3) array of numbers"),
        (set_person("camT", 1, 4, None), "row 1, person 4: camT: expected 3 numbers"),
        (set_person("camK", 2, 0, {"fx": 1}), "row 2, person 0: camK: expected a (3, 3) array of numbers, got a dict"),
        (lambda df: df.__setitem__("imgPath", ["a.png", None, "c.png"]), "row 1: imgPath: expected a string"),
        (lambda df: df.at.__setitem__((1, "occlusion"), "abc"), "row 1: column 'occlusion' has 1 entries (str 'abc')"),
    ],
)
def test_agora_malformed_fields_name_file_row_person_field(tmp_path, edit, message):
    path = agora_copy(tmp_path, edit)
    res = hpe("relabel-agora", path, "-o", tmp_path / "o.csv", "--rejects", tmp_path / "r.csv", "-q")
    one_error(res, path, message)
    assert not (tmp_path / "o.csv").exists() and not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize(
    "edit, detail",
    [
        (set_person("camR", 1, 0, 2 * np.eye(3)), "camR not orthonormal"),
        (set_person("camK", 1, 0, np.zeros((3, 3))), "camK focal length not positive"),
        (set_person("camK", 1, 0, np.array([[1000.0, 0, 0], [0, 1000, 0], [0, 0, 1]])), "camK principal point"),
        (set_person("camK", 1, 0, np.array([[1000.0, 0, 960], [0, 1000, 540], [0, 0, 0]])), "camK not a pinhole"),
        (set_person("occlusion", 1, 0, 250.0), "occlusion out of range"),
    ],
)
def test_agora_invalid_values_refused_or_rejected(tmp_path, edit, detail):
    path = agora_copy(tmp_path, edit)
    # without --rejects: an error naming the file, the person and the field; nothing written
    one_error(hpe("relabel-agora", path, "-o", tmp_path / "o.csv", "-q"), path, "row 1, person 0", detail)
    assert not (tmp_path / "o.csv").exists()
    # with --rejects: the person is a 'bad input' reject whose detail names the field, the others are labelled
    res = hpe("relabel-agora", path, "-o", tmp_path / "o.csv", "--rejects", tmp_path / "r.csv", "-q")
    assert res.exit_code == 0, res.output
    rj = pd.read_csv(tmp_path / "r.csv")
    hit = rj[(rj["row"] == 1) & (rj["person"] == 0)]
    assert list(hit["reason"]) == ["bad input"] and detail in hit["detail"].iloc[0]
    n_people = sum(len(v) for v in pd.read_pickle(AGORA_PKL)["isValid"])
    assert len(pd.read_csv(tmp_path / "o.csv")) + len(rj) == n_people


def test_agora_same_file_twice_or_same_name_refused(tmp_path):
    a = tmp_path / "a" / "val_withjv.pkl"
    a.parent.mkdir()
    shutil.copy(AGORA_PKL, a)
    link = tmp_path / "link_withjv.pkl"
    os.link(a, link)
    other = tmp_path / "b" / "val_withjv.pkl"
    other.parent.mkdir()
    shutil.copy(AGORA_PKL, other)
    out = tmp_path / "o.csv"
    one_error(hpe("relabel-agora", a, a, "-o", out, "-q"), f"{a} and {a}", "given twice")
    one_error(hpe("relabel-agora", a, link, "-o", out, "-q"), f"{a} and {link}", "given twice")
    one_error(hpe("relabel-agora", a, other, "-o", out, "-q"), f"{a} and {other}", "two dataframes named")
    assert not out.exists()
    assert hpe("relabel-agora", a, "-o", out, "-q").exit_code == 0  # the file alone is fine


# ================================================================== .mat
def mat_folder(tmp_path, key, value):
    folder = tmp_path / "aflw"
    folder.mkdir()
    for f in AFLW.glob("*.mat"):
        shutil.copy(f, folder / f.name)
    bad = folder / "image00251.mat"
    m = {k: v for k, v in scipy.io.loadmat(bad).items() if not k.startswith("__")}
    m[key] = value
    scipy.io.savemat(bad, m)
    return folder, bad


def _cell():
    c = np.empty((1, 7), dtype=object)
    c[0, :] = [np.array([[0.1]])] * 7
    return c


@pytest.mark.parametrize(
    "key, value, got",
    [
        ("Pose_Para", _cell(), "got a cell array (1, 7)"),
        ("Pose_Para", {"pitch": 0.1, "yaw": 0.2}, "got a struct"),
        ("Pose_Para", "abcdefg", "got a char array"),
        ("Pose_Para", np.zeros((3, 3)), "got shape (3, 3)"),
        ("pt2d", "xy", "got a char array"),
        ("pt3d_68", _cell(), "got a cell array"),
    ],
)
def test_mat_fields_named_with_the_mat_file(tmp_path, key, value, got):
    folder, bad = mat_folder(tmp_path, key, value)
    for cmd in (
        ["convert", folder, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "whenet"],
        ["audit", folder],
    ):
        one_error(hpe(*cmd, "-q"), f"{bad}: {key}: expected", got)


# ================================================================== Panoptic calibration
def calib_copy(tmp_path, edit):
    doc = json.loads((SYNTH / f"calibration_{SYNTH.name}.json").read_text())
    edit(doc["cameras"])
    path = tmp_path / "calibration_x.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda c: c[1].update(name=None),
            "camera 1: name: expected a camera name of letters, digits, '_', '-' or '.', got None",
        ),
        (lambda c: c[1].update(name=""), "camera 1: name: expected a camera name"),
        (lambda c: c[1].update(name=7), "camera 1: name: expected a camera name"),
        (
            lambda c: c[2].update(distCoef=[1e10, 0, 0, 0, 0]),
            "camera 2 (00_02): distCoef: expected radial coefficients",
        ),
        (
            lambda c: c[2].update(distCoef=[0, 0, 0.5, 0, 0]),
            "distCoef: expected tangential coefficients |p1|, |p2| <= 0.1",
        ),
        (lambda c: c[2].update(distCoef=[-3.0, 0, 0, 0, 0]), "distCoef: expected a lens model that"),
        (lambda c: c[2].update(distCoef=["a", 0, 0, 0, 0]), "distCoef: expected numbers, got a list"),
        (lambda c: c[0].update(K=[[0, 0, 0], [0, 0, 0], [0, 0, 0]]), "camera 0 (00_00): expected K ="),
        (
            lambda c: c[0].update(K=[[1000, 0, 5000], [0, 1000, 540], [0, 0, 1]]),
            "K: expected the principal point inside",
        ),
        (lambda c: c[0].update(R=[[2, 0, 0], [0, 2, 0], [0, 0, 2]]), "expected R to be a rotation"),
        (lambda c: c[0].update(R=[[1, 0, 0], [0, 1, 0], [0, 0, -1]]), "expected R to be a rotation"),
        (lambda c: c[0].update(t="far"), "camera 0 (00_00): t: expected numbers, got str 'far'"),
        (lambda c: c[0].update(resolution=["1920", "1080"]), "resolution: expected [width, height] as integers"),
        (lambda c: c[0].update(panel="abc"), "panel: expected an integer, got str 'abc'"),
        (lambda c: c[0].update(type=None), "type: expected a string"),
        (lambda c: c.__setitem__(3, "00_03"), "camera 3: expected an object"),
    ],
)
def test_panoptic_calibration_checked_as_what_it_is(tmp_path, edit, message):
    path = calib_copy(tmp_path, edit)
    with pytest.raises(HpeError) as err:
        pan.read_calibration(path)
    assert str(path) in str(err.value) and message in str(err.value), str(err.value)


def test_panoptic_null_camera_name_is_a_calibration_error_in_the_cli(tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(SYNTH, seq)
    calib = seq / f"calibration_{SYNTH.name}.json"
    doc = json.loads(calib.read_text())
    doc["cameras"][1]["name"] = None
    calib.write_text(json.dumps(doc))
    one_error(hpe("relabel-panoptic", seq, "-o", tmp_path / "o.csv", "-q"), calib, "camera 1: name")


@pytest.mark.skipif(not (REAL / "panoptic_160906_pizza1").is_dir(), reason="../shared/realdata is not available")
def test_real_calibration_passes_and_the_distortion_bound_has_margin():
    """The 520 real cameras pass; their lens models stay far inside the bound (the stated margin)."""
    path = REAL / "panoptic_160906_pizza1" / "calibration_160906_pizza1.json"
    cams = pan.read_calibration(path)
    assert len(cams) == 520
    assert np.abs(cams.dist[:, [2, 3]]).max() < MAX_TANGENTIAL / 30
    # scaling every coefficient by 3 is still a real lens here; the 1e10 of the issue is not
    assert not any(distortion_problems(3 * cams.dist, cams.K, cams.width, cams.height))
    assert distortion_problem([1e10, 0, 0, 0, 0], cams.K[0], 1920, 1080)


# ================================================================== Panoptic faces and archives
def test_huge_frame_number_is_one_line(tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(SYNTH, seq)
    first = sorted((seq / "hdFace3d").iterdir())[0]
    huge = seq / "hdFace3d" / ("faceRecon3D_hd" + "9" * 25 + ".json")
    shutil.copy(first, huge)
    one_error(hpe("relabel-panoptic", seq, "-o", tmp_path / "o.csv", "-q"), huge, "frame number", "out of range")


@pytest.mark.parametrize(
    "member",
    [
        "../x/faceRecon3D_hd00000001.json",
        "/abs/faceRecon3D_hd00000001.json",
        "hdFace3d/../../faceRecon3D_hd00000001.json",
    ],
)
def test_face_tar_traversal_refused(tmp_path, member):
    src = sorted((SYNTH / "hdFace3d").iterdir())[0]
    tar = tmp_path / "hdFace3d.tar"
    with tarfile.open(tar, "w", format=tarfile.USTAR_FORMAT) as tf:
        tf.add(src, arcname=f"hdFace3d/{src.name}")
        info = tarfile.TarInfo(member)
        data = src.read_bytes()
        info.size = len(data)
        tf.addfile(info, io.BytesIO(data))
    for index in (pan.tar_frames, pan._tar_frames_tarfile):
        with pytest.raises(HpeError, match="refused") as err:
            index(tar)
        assert str(tar) in str(err.value) and repr(member) in str(err.value)


@pytest.mark.parametrize(
    "value, message",
    [
        ("abc", "person 0: id: expected an integer, got str 'abc'"),
        (1e30, "person 0: id: expected an integer"),
        (True, "person 0: id: expected an integer, got bool True"),
    ],
)
def test_face_person_id(tmp_path, value, message):
    doc = json.loads(sorted((SYNTH / "hdFace3d").iterdir())[0].read_text())
    doc["people"][0]["id"] = value
    path = tmp_path / "faceRecon3D_hd00000007.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(HpeError, match=message):
        pan.read_face_frame(path)


@pytest.mark.parametrize(
    "value, message",
    [
        ("1.5", r"person 0 \(id \d+\): landmarks: expected numbers \(or null\), got str '1.5' at index 4"),
        (True, r"landmarks: expected numbers \(or null\), got bool True at index 4"),
        ([1.0, 2.0], r"landmarks: expected numbers \(or null\), got a list"),
    ],
)
def test_face_landmark_values(tmp_path, value, message):
    doc = json.loads(sorted((SYNTH / "hdFace3d").iterdir())[0].read_text())
    doc["people"][0]["face70"]["landmarks"][4] = value
    path = tmp_path / "faceRecon3D_hd00000008.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(HpeError, match=message):
        pan.read_face_frame(path)


# ================================================================== BIWI
def bin_payload(centre=(50.0, 40.0, 880.0), angles=(-7.0, 3.0, -2.0)):
    return np.array([*centre, *angles], dtype="<f4").tobytes()


def make_tgz(path, members):
    with tarfile.open(path, "w:gz") as tf:
        for name, data in members:
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
    return path


@pytest.mark.parametrize(
    "names, message",
    [
        (
            ["01/frame_00004_pose.bin", "01/frame_00005_pose.bin", "01/frame_00004_pose.bin"],
            "member 01/frame_00004_pose.bin appears twice",
        ),
        (
            ["01/frame_00004_pose.bin", "./01/frame_00004_pose.bin"],
            "01/frame_00004_pose.bin and ./01/frame_00004_pose.bin are both sequence 01 frame 4",
        ),
        (["01/frame_00004_pose.bin", "../01/frame_00005_pose.bin"], "member '../01/frame_00005_pose.bin': refused"),
        (["/01/frame_00004_pose.bin"], "member '/01/frame_00004_pose.bin': refused: an absolute name"),
        (["01/frame_99999999999999999999_pose.bin"], "frame number 99999999999999999999 is out of range"),
    ],
)
def test_biwi_tgz_duplicates_and_traversal(tmp_path, names, message):
    tgz = make_tgz(tmp_path / "db_annotations.tgz", [(n, bin_payload()) for n in names])
    one_error(hpe("biwi", tgz, "-o", tmp_path / "o.csv", "-q"), tgz, message)
    assert not (tmp_path / "o.csv").exists()


def test_biwi_folder_duplicate_frames_name_both(tmp_path):
    for sub in ("a/01", "b/01"):
        (tmp_path / sub).mkdir(parents=True)
        (tmp_path / sub / "frame_00004_pose.bin").write_bytes(bin_payload())
    with pytest.raises(
        HpeError, match="a/01/frame_00004_pose.bin and b/01/frame_00004_pose.bin are both sequence 01 frame 4"
    ):
        biwi.read_biwi(tmp_path)


@pytest.mark.parametrize(
    "payload, message",
    [
        (bin_payload(centre=(50, 40, -880)), "head centre: expected a point in front of the camera"),
        (bin_payload(centre=(5e5, 40, 880)), "head centre: expected a point in front of the camera"),
        (bin_payload(angles=(-7, 200, -2)), "yaw: expected degrees within +-90"),
        (bin_payload(angles=(1e30, 3, -2)), "pitch: expected degrees within +-180"),
    ],
    ids=["behind", "far", "yaw", "pitch"],
)
def test_biwi_bin_ranges(tmp_path, payload, message):
    (tmp_path / "01").mkdir()
    path = tmp_path / "01" / "frame_00004_pose.bin"
    path.write_bytes(payload)
    with pytest.raises(HpeError, match=re.escape(message)):
        biwi.read_pose_bin(path)


@needs_real
@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda v: v.__setitem__(slice(0, 9), [0] * 9), "K: expected positive focal lengths"),
        (lambda v: v.__setitem__(2, 5000), "K: expected the principal point inside the 640x480 image"),
        (lambda v: v.__setitem__(9, 1e10), "distortion: expected radial coefficients"),
        (lambda v: v.__setitem__(slice(13, 22), [2, 0, 0, 0, 2, 0, 0, 0, 2]), "R: expected a rotation matrix"),
        (lambda v: v.__setitem__(25, 640.5), "width, height: expected positive whole numbers"),
        (lambda v: v.__setitem__(26, 0), "width, height: expected positive whole numbers"),
    ],
)
def test_biwi_calibration_checked(tmp_path, edit, message):
    v = [float(x) for x in (REAL / "biwi" / "hpdb" / "01" / "rgb.cal").read_text().split()]
    edit(v)
    (tmp_path / "01").mkdir()
    path = tmp_path / "01" / "rgb.cal"
    path.write_text(" ".join(repr(x) for x in v))
    with pytest.raises(HpeError, match=re.escape(message)):
        biwi.read_calibration(path)


@needs_real
def test_real_biwi_files_pass():
    for name in ("rgb.cal", "depth.cal"):
        biwi.read_calibration(REAL / "biwi" / "hpdb" / "01" / name)
    assert len(biwi.read_biwi(REAL / "biwi" / "hpdb")) == 1
    assert len(biwi.read_biwi(REAL / "biwi" / "db_annotations_subset")) > 0  # .bin centres and angles in range


# ================================================================== video frames against the calibration
@pytest.fixture(scope="module")
def small_video(tmp_path_factory):
    gen = sample_data_script()
    root = tmp_path_factory.mktemp("vid") / "seqV"
    gen.make_synthetic(root, n_frames=4, n_people=1, n_cameras=1, first_frame=0, special=False)
    paths = gen.write_videos(root, last_frame=3, size=(192, 108), cameras=1)
    return paths[0]


def test_video_size_checked_against_calibration(small_video):
    v = VideoFrames(small_video)
    assert v.size() == (192, 108)
    assert [f for f, img, _ in v.read([0, 2]) if img is not None] == [0, 2]  # no expected size: unchanged
    ok = VideoFrames(small_video, expected_size=(192, 108))
    assert ok.check_size() == (192, 108)
    assert all(img.shape == (108, 192, 3) for _, img, _ in ok.read([1, 3]))
    wrong = VideoFrames(small_video, expected_size=(1920, 1080))
    for call in (wrong.check_size, lambda: list(wrong.read([0, 1])), lambda: v.check_size((1920, 1080))):
        with pytest.raises(HpeError) as err:
            call()
        msg = str(err.value)
        assert str(small_video) in msg and "192x108" in msg and "1920x1080" in msg and "\n" not in msg
    with pytest.raises(HpeError, match="expected_size"):
        VideoFrames(small_video, expected_size=(0, 10))


# ================================================================== DAD-3DHeads
@pytest.mark.parametrize(
    "field, value, message",
    [
        ("bbox", [1, "2", 3, 4], "item 1: bbox: expected [x, y, w, h] (4 numbers)"),
        ("item_id", None, "item 1: item_id: expected a non-empty string, got None"),
        ("item_id", "../../etc", "item 1: item_id: expected a file name"),
        ("img_path", "../../etc/passwd", "item 1: img_path: expected a relative image path"),
        ("attributes", ["a"], "item 1: attributes: expected an object"),
    ],
)
def test_dad3dheads_item_fields(tmp_path, field, value, message):
    from hpe_cli.datasets.dad3dheads import read_dad3dheads

    sub = tmp_path / "val"
    sub.mkdir()
    item = {"item_id": "a", "img_path": "images/a.png", "bbox": [1, 2, 3, 4], "attributes": {}}
    item[field] = value
    (sub / "val.json").write_text(json.dumps([item]))
    with pytest.raises(HpeError) as err:
        read_dad3dheads(sub)
    assert "val.json" in str(err.value) and message in str(err.value), str(err.value)


# ================================================================== 300W-LP zip members
@pytest.mark.parametrize(
    "extra, message",
    [
        ("300W_LP/IBUG/../../evil_0.mat", "member '300W_LP/IBUG/../../evil_0.mat': refused: a name with '..'"),
        ("/300W_LP/IBUG/IBUG_x_0.mat", "member '/300W_LP/IBUG/IBUG_x_0.mat': refused: an absolute name"),
        ("300W_LP/IBUG/IBUG_image_008_1_0.mat", "member 300W_LP/IBUG/IBUG_image_008_1_0.mat appears twice"),
    ],
)
def test_w300lp_zip_members(tmp_path, extra, message):
    import warnings
    import zipfile

    src = REAL / "300wlp_face3d" / "IBUG_image_008_1_0.mat"
    if not src.exists():
        pytest.skip("../shared/realdata is not available")
    arc = tmp_path / "300W-LP.zip"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # zipfile warns about the duplicate name
        with zipfile.ZipFile(arc, "w") as z:
            z.writestr("300W_LP/IBUG/IBUG_image_008_1_0.mat", src.read_bytes())
            z.writestr(extra, src.read_bytes())
    one_error(hpe("convert", arc, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "whenet", "-q"), arc, message)
    assert not (tmp_path / "o.csv").exists()
