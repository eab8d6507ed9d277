"""Structurally wrong values in every dataset reader's fields (Hypothesis).

The valid bases are real files (``sample_data``, ``tests/data/agora``, ``../shared/realdata``); one field of
one record is replaced by a value of the wrong type or shape (None, strings, bools, huge integers, NaN,
nested or ragged lists, dicts, MATLAB cell arrays, structs and char arrays). Every reader must either
accept the file (the value was usable after all, or it becomes a per-record reject with a reason naming
the field) or raise ``HpeError`` whose one line names the file, the record and the field -- never any
other exception.
"""

from __future__ import annotations

import io
import json
import pickle
import re
import tarfile
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import sample_data_script
from hpe_cli.errors import HpeError

from .conftest import AFLW, AGORA_PKL, ROOT, SYNTH

REALDATA = ROOT.parent / "shared" / "realdata"
FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)

# ------------------------------------------------------------------ values of the wrong kind
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=6),
    st.integers(-(10**30), 10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.just(""),
    st.just("no"),
    st.just("1.5"),
)
nested = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=3), inner, max_size=2)),
    max_leaves=8,
)
json_values = nested.filter(lambda v: _jsonable(v))
#: standard JSON only (no NaN/Infinity literals): for readers whose JSON parser refuses those as a whole
strict_json_values = nested.filter(lambda v: _jsonable(v, strict=True))


def _jsonable(v, strict: bool = False) -> bool:
    try:
        json.dumps(v, allow_nan=not strict)
        return True
    except (TypeError, ValueError, OverflowError):
        return False


@st.composite
def arrays(draw):
    """numpy arrays of the wrong kind or shape: str, object (nested cells), bool, complex, odd shapes."""
    kind = draw(st.sampled_from(["str", "object", "bool", "complex", "float", "empty", "int"]))
    shape = tuple(draw(st.lists(st.integers(0, 4), min_size=0, max_size=3)))
    n = int(np.prod(shape)) if shape else 1
    if kind == "str":
        return np.array(["x"] * n).reshape(shape)
    if kind == "object":
        a = np.empty(n, dtype=object)
        for k in range(n):
            a[k] = draw(st.one_of(st.text(max_size=3), st.none(), st.just([1.0, "a"])))
        return a.reshape(shape)
    if kind == "bool":
        return np.ones(shape, dtype=bool)
    if kind == "complex":
        return np.ones(shape) * 1j
    if kind == "empty":
        return np.zeros((0, 3))
    if kind == "int":
        return np.arange(n, dtype=np.int64).reshape(shape)
    return np.full(shape, draw(st.floats(allow_nan=True, allow_infinity=True)))


bad_values = st.one_of(nested, arrays())


def _one_line_naming(exc: HpeError, path, record_words, field_words):
    msg = str(exc)
    assert "\n" not in msg, msg
    assert str(path) in msg or Path(path).name in msg, (path, msg)
    if record_words:
        assert any(w in msg for w in record_words), (record_words, msg)
    assert any(w in msg for w in field_words), (field_words, msg)
    return msg


# ------------------------------------------------------------------ AGORA
AGORA_PERSON_COLS = ["isValid", "occlusion", "cam_j3d", "camR", "camT", "camK"]


@pytest.fixture(scope="module")
def agora_df():
    from hpe_cli.datasets.agora import load_dataframe

    return load_dataframe(AGORA_PKL)


@FUZZ
@given(
    col=st.sampled_from(AGORA_PERSON_COLS + ["imgPath"]),
    row=st.integers(0, 2),
    person=st.integers(0, 3),
    whole=st.booleans(),
    value=bad_values,
)
def test_agora_fields(agora_df, col, row, person, whole, value):
    from hpe_cli.datasets.agora import read_agora
    from hpe_cli.pipelines.relabel.agora import Config, relabel_people

    df = agora_df.copy()
    cells = df[col].tolist()
    if whole or col == "imgPath":
        cells[row] = value
    else:
        cell = list(cells[row])
        cell[person % len(cell)] = value
        cells[row] = cell
    df[col] = pd.Series(cells, dtype=object)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "fuzz_withjv.pkl"
        path.write_bytes(pickle.dumps(df, protocol=4))
        try:
            people = read_agora(path)
        except HpeError as exc:
            _one_line_naming(exc, path, [f"row {row}"], [col, "isValid"])
            return
        res = relabel_people(people, Config())  # what was accepted must relabel without an exception
        assert len(res["table"]["row"]) + len(res["rejects"]["row"]) == len(people)
        bad = people.reason[people.row == row]
        for why in bad[bad != ""]:
            assert any(c in why for c in AGORA_PERSON_COLS + ["imgPath", "face joints"]), why


# ------------------------------------------------------------------ .mat (300W-LP / AFLW2000-3D)
def _mat_values():
    cell = np.empty((1, 7), dtype=object)
    cell[0, :] = [np.array([[0.1]])] * 7
    nested_cell = np.empty((1, 2), dtype=object)
    nested_cell[0, 0], nested_cell[0, 1] = cell, "text"
    return st.one_of(
        st.sampled_from(
            [
                cell,
                nested_cell,
                {"pitch": 0.1, "yaw": np.zeros(3)},
                "abcdefg",
                "",
                np.ones((1, 7), dtype=bool),
                np.ones((1, 7)) * 1j,
                np.zeros((0, 0)),
                np.zeros((3, 3)),
                np.zeros((1, 40)),
                np.array([[1.0, 2.0]]),
            ]
        ),
        arrays().filter(lambda a: a.dtype.kind != "O" or a.size),
    )


@FUZZ
@given(key=st.sampled_from(["Pose_Para", "pt2d", "pt3d_68"]), value=_mat_values())
def test_mat_fields(key, value):
    import scipy.io

    from hpe_cli.datasets.mat import read_mat

    src = sorted(AFLW.glob("*.mat"))[0]
    m = {k: v for k, v in scipy.io.loadmat(src).items() if not k.startswith("__")}
    m[key] = value
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "image_fuzz.mat"
        try:
            scipy.io.savemat(path, m)
        except Exception:  # savemat cannot store it: nothing to read
            return
        try:
            rec = read_mat(path)
        except HpeError as exc:
            _one_line_naming(exc, path, None, [key])
            return
        assert rec["pose"].shape == (7,) and rec["pose"].dtype == np.float64


@FUZZ
@given(key=st.sampled_from(["pts_2d", "pts_3d"]), value=_mat_values())
def test_w300lp_landmark_fields(key, value):
    import scipy.io

    from hpe_cli.datasets.w300lp import read_pts

    m = {"pts_2d": np.zeros((68, 2)), "pts_3d": np.zeros((68, 2)), key: value}
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "IBUG_x_0_pts.mat"
        try:
            scipy.io.savemat(path, m)
        except Exception:
            return
        try:
            read_pts(path)
        except HpeError as exc:
            _one_line_naming(exc, path, None, [key, "pts_2d", "pts_3d"])


# ------------------------------------------------------------------ Panoptic
CAMERA_FIELDS = ["name", "type", "K", "R", "t", "distCoef", "resolution", "panel", "node"]


@FUZZ
@given(
    field=st.sampled_from(CAMERA_FIELDS),
    cam=st.integers(0, 8),
    value=json_values,
    where=st.sampled_from(["field", "element", "camera"]),
)
def test_panoptic_calibration_fields(field, cam, value, where):
    from hpe_cli.datasets.panoptic import read_calibration

    doc = json.loads((SYNTH / f"calibration_{SYNTH.name}.json").read_text())
    c = doc["cameras"][cam % len(doc["cameras"])]
    if where == "camera":
        doc["cameras"][cam % len(doc["cameras"])] = value
    elif where == "element" and isinstance(c.get(field), list) and c[field]:
        target = c[field]
        if isinstance(target[0], list) and target[0]:
            target = target[0]
        target[0] = value
    else:
        c[field] = value
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "calibration_fuzz.json"
        path.write_text(json.dumps(doc))
        try:
            read_calibration(path)
        except HpeError as exc:
            fields = CAMERA_FIELDS + ["expected an object"]
            _one_line_naming(exc, path, [f"camera {cam % len(doc['cameras'])}", "camera "], fields)


FACE_TARGETS = [
    "person",
    "id",
    "face70",
    "landmarks",
    "averageScore",
    "averageReproError",
    "landmark",
    "score",
    "people",
]


@FUZZ
@given(target=st.sampled_from(FACE_TARGETS), index=st.integers(0, 209), value=json_values)
def test_panoptic_face_fields(target, index, value):
    from hpe_cli.datasets.panoptic import read_face_frame

    src = sorted((SYNTH / "hdFace3d").glob("faceRecon3D_hd*.json"))[0]
    doc = json.loads(src.read_text())
    person = doc["people"][0]
    if target == "person":
        doc["people"][0] = value
    elif target == "people":
        doc["people"] = value
    elif target == "id":
        person["id"] = value
    elif target == "face70":
        person["face70"] = value
    elif target == "landmark":
        person["face70"]["landmarks"][index] = value
    elif target == "score":
        person["face70"]["averageScore"][index % 70] = value
    else:
        person["face70"][target] = value
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / src.name
        path.write_text(json.dumps(doc))
        try:
            f = read_face_frame(path)
        except HpeError as exc:
            _one_line_naming(
                exc,
                path,
                ["person 0", "people"],
                ["id", "face70", "landmarks", "averageScore", "averageReproError", "people", "expected"],
            )
            return
        assert f["landmarks"].dtype == np.float64 and f["landmarks"].shape[1:] == (70, 3)


@FUZZ
@given(digits=st.text(alphabet="0123456789", min_size=1, max_size=40))
def test_panoptic_frame_numbers_in_names(digits):
    from hpe_cli.datasets.panoptic import face_frames, read_face_frame

    src = sorted((SYNTH / "hdFace3d").glob("faceRecon3D_hd*.json"))[0]
    with tempfile.TemporaryDirectory() as d:
        face = Path(d) / "hdFace3d"
        face.mkdir()
        path = face / f"faceRecon3D_hd{digits}.json"
        path.write_bytes(src.read_bytes())
        try:
            frames = face_frames(d)
            f = read_face_frame(path)
        except HpeError as exc:
            _one_line_naming(exc, path, None, ["frame number"])
            return
        assert list(frames) == [int(digits)] and f["frame"] == int(digits)


# ------------------------------------------------------------------ BIWI
BAD_TOKENS = st.one_of(
    st.sampled_from(
        ["nan", "inf", "-inf", "1e400", "abc", "1,5", "0x10", "True", "--1", "1e30", "-1e30", "0", "-700", "1e-320"]
    ),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
)


def _biwi_file(name):
    p = REALDATA / "biwi" / "hpdb" / "01" / name
    if not p.exists():
        pytest.skip("../shared/realdata/biwi is not available")
    return p


@FUZZ
@given(
    which=st.sampled_from(["frame_00003_pose.txt", "rgb.cal", "depth.cal"]),
    index=st.integers(0, 30),
    token=BAD_TOKENS,
    drop=st.booleans(),
)
def test_biwi_text_fields(which, index, token, drop):
    from hpe_cli.datasets.biwi import read_calibration, read_pose_txt

    src = _biwi_file(which)
    tokens = src.read_text().split()
    k = index % len(tokens)
    if drop:
        del tokens[k]
    else:
        tokens[k] = token
    with tempfile.TemporaryDirectory() as d:
        seq = Path(d) / "01"
        seq.mkdir()
        path = seq / which
        path.write_text(" ".join(tokens) + "\n")
        reader = read_pose_txt if which.endswith(".txt") else read_calibration
        try:
            reader(path)
        except HpeError as exc:
            _one_line_naming(
                exc, path, None, ["number", "rotation", "centre", "K", "distortion", "R", "t", "width", "finite"]
            )


@FUZZ
@given(index=st.integers(0, 5), value=st.floats(width=32, allow_nan=True, allow_infinity=True))
def test_biwi_bin_fields(index, value):
    from hpe_cli.datasets.biwi import read_pose_bin

    tgz = REALDATA / "biwi" / "db_annotations.tgz"
    if not tgz.exists():
        pytest.skip("../shared/realdata/biwi is not available")
    with tarfile.open(tgz) as tf:
        m = next(m for m in tf if m.isfile() and m.name.endswith("_pose.bin"))
        raw = tf.extractfile(m).read()
    v = np.frombuffer(raw, dtype="<f4").copy()
    v[index] = value
    with tempfile.TemporaryDirectory() as d:
        seq = Path(d) / "01"
        seq.mkdir()
        path = seq / "frame_00004_pose.bin"
        path.write_bytes(v.astype("<f4").tobytes())
        try:
            out = read_pose_bin(path)
        except HpeError as exc:
            _one_line_naming(exc, path, None, ["centre", "pitch", "yaw", "roll", "finite"])
            return
        assert np.isfinite(out).all()


@FUZZ
@given(
    names=st.lists(
        st.sampled_from(
            [
                "01/frame_00004_pose.bin",
                "./01/frame_00004_pose.bin",
                "../01/frame_00005_pose.bin",
                "/01/frame_00006_pose.bin",
                "01/../../frame_00007_pose.bin",
                "02/frame_00004_pose.bin",
                "01/frame_99999999999999999999_pose.bin",
                "x/02/frame_00004_pose.bin",
                "readme.txt",
            ]
        ),
        min_size=1,
        max_size=5,
    )
)
def test_biwi_tgz_member_names(names):
    from hpe_cli.datasets.biwi import read_biwi_tgz

    payload = np.array([50.0, 40.0, 880.0, -7.0, 3.0, -2.0], dtype="<f4").tobytes()
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "db_annotations.tgz"
        with tarfile.open(path, "w:gz") as tf:
            for n in names:
                info = tarfile.TarInfo(n)
                info.size = len(payload)
                tf.addfile(info, io.BytesIO(payload))
        try:
            t = read_biwi_tgz(path)
        except HpeError as exc:
            msg = _one_line_naming(exc, path, None, ["member", "frame", "no NN/"])
            bad = [n for n in names if ".." in n.split("/") or n.startswith("/")]
            if bad and "refused" in msg:
                assert any(repr(n) in msg for n in bad), msg
            return
        keys = list(zip(t["sequence"], t["frame"]))
        assert len(keys) == len(set(keys))  # never a duplicated frame
        assert not any(".." in f.split("/") or f.startswith("/") for f in t["file"])


# ------------------------------------------------------------------ DAD-3DHeads
ITEM_FIELDS = ["item_id", "img_path", "bbox", "attributes", "model_view_matrix"]


@FUZZ
@given(field=st.sampled_from(ITEM_FIELDS), value=strict_json_values, element=st.booleans())
def test_dad3dheads_fields(field, value, element):
    from hpe_cli.datasets.dad3dheads import read_dad3dheads

    with tempfile.TemporaryDirectory() as d:
        sub = Path(d) / "val"
        (sub / "annotations").mkdir(parents=True)
        items = [
            {
                "item_id": f"item{k:03d}",
                "annotation_path": f"annotations/item{k:03d}.json",
                "img_path": f"images/item{k:03d}.png",
                "bbox": [10.0, 20.0, 30.0, 40.0],
                "attributes": {"quality": "hq", "pose": "frontal"},
            }
            for k in range(2)
        ]
        mv = [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, -5.0], [0, 0, 0, 1.0]]
        ann = {"model_view_matrix": mv}
        if field == "model_view_matrix":
            if element:
                mv[1][2] = value
            else:
                ann["model_view_matrix"] = value
        elif element and field == "bbox":
            items[1]["bbox"][2] = value
        elif element and field == "attributes":
            items[1]["attributes"]["pose"] = value
        else:
            items[1][field] = value
        (sub / "val.json").write_text(json.dumps(items))
        for k in range(2):
            (sub / "annotations" / f"item{k:03d}.json").write_text(
                json.dumps(
                    ann
                    if k == 1
                    else {"model_view_matrix": [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, -5.0], [0, 0, 0, 1.0]]}
                )
            )
        try:
            read_dad3dheads(sub)
        except HpeError as exc:
            msg = str(exc)
            assert "\n" not in msg and ("val.json" in msg or "item001.json" in msg), msg
            assert re.search(r"item 2|item001", msg), msg
            assert any(f in msg for f in ITEM_FIELDS), msg


# ------------------------------------------------------------------ Panoptic HD video
@pytest.fixture(scope="module")
def video_bytes(tmp_path_factory):
    gen = sample_data_script()
    root = tmp_path_factory.mktemp("video") / "seqV"
    gen.make_synthetic(root, n_frames=4, n_people=1, n_cameras=1, first_frame=0, special=False)
    return gen.write_videos(root, last_frame=5, size=(192, 108), cameras=1)[0].read_bytes()


@FUZZ
@given(
    cut=st.booleans(),
    where=st.integers(0, 10**6),
    flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), max_size=6),
    expected=st.sampled_from([(192, 108), (1920, 1080), None]),
)
def test_video_bytes(video_bytes, cut, where, flips, expected):
    from hpe_cli.datasets.panoptic_video import VideoFrames

    data = bytearray(video_bytes)
    if cut:
        data = data[: where % len(data)]
    else:
        for off, x in flips:
            data[off % len(data)] ^= x
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "hd_00_00.mp4"
        path.write_bytes(bytes(data))
        try:
            got = list(VideoFrames(path, expected_size=expected).read([0, 3, 5, 9]))
        except HpeError as exc:
            msg = _one_line_naming(exc, path, None, ["pixels", "frame"])
            assert expected is not None and f"{expected[0]}x{expected[1]}" in msg, msg
            return
        assert [f for f, _, _ in got] == [0, 3, 5, 9]
        for _, img, reason in got:
            assert (img is None) == bool(reason)
            if img is not None and expected is not None:
                assert img.shape == (expected[1], expected[0], 3)
