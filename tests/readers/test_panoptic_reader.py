"""CMU Panoptic readers: the real 160906_pizza1 files, the synthetic sample, and broken files."""

import json
from pathlib import Path

import numpy as np
import pytest

from hpe_cli.datasets import panoptic as pan
from hpe_cli.errors import HpeError

ROOT = Path(__file__).resolve().parents[2]
SYNTH = ROOT / "sample_data" / "panoptic_synth"


@pytest.fixture
def real(realdata):
    return realdata / "panoptic_160906_pizza1"


def test_real_calibration_all_types(real):
    cams = pan.read_calibration(real / "calibration_160906_pizza1.json")
    assert len(cams) == 520
    types, counts = np.unique(cams.types, return_counts=True)
    assert dict(zip(types, counts)) == {"hd": 31, "vga": 479, "kinect-color": 10}
    hd = cams.select("hd")
    assert len(hd) == 31 and list(hd.names[:2]) == ["00_00", "00_01"]
    assert set(hd.panel) == {0} and sorted(hd.node) == list(range(31))
    c0 = hd.select("00_00")
    np.testing.assert_allclose(c0.K[0], [[1634.03, 0, 942.79], [0, 1629.73, 558.29], [0, 0, 1]], atol=0.01)
    np.testing.assert_allclose(c0.t[0], [20.9, 127.22, 283.12], atol=0.01)
    np.testing.assert_allclose(c0.dist[0], [-0.2224, 0.1992, 8.7e-5, 9.8e-4, 0.0238], atol=5e-5)
    assert (c0.width[0], c0.height[0]) == (1920, 1080)
    # rotations are proper, and names select in the given order
    assert np.allclose(np.linalg.det(hd.R), 1.0)
    assert list(cams.select("00_08,00_00").names) == ["00_08", "00_00"]
    assert list(cams.select(["kinect-color"]).names)[:2] == ["50_01", "50_02"]


def test_real_face_frames(real):
    frames = pan.face_frames(real)
    assert list(frames) == [1147, 1613, 2319, 3476, 3961, 4905, 5777, 6078, 6328, 6577]
    assert pan.face_frames(real / "hdFace3d") == frames
    f = pan.read_face_frame(frames[1147])
    assert f["frame"] == 1147 and f["version"] == 0.5 and np.isnan(f["univTime"])
    assert f["landmarks"].shape == (5, 70, 3) and f["score"].shape == (5, 70)
    raw = json.loads(frames[1147].read_text())["people"][0]["face70"]
    np.testing.assert_array_equal(f["landmarks"][0].reshape(-1), raw["landmarks"])
    np.testing.assert_array_equal(f["reproj_error"][0], raw["averageReproError"])
    both = pan.read_face_frames({k: frames[k] for k in (5777, 6577)})
    assert list(np.unique(both["frame"])) == [5777, 6577] and len(both["frame"]) == 12
    # frame 5777 person 2 is the almost failed face of PROVENANCE.md (mean score 0.013)
    i = np.flatnonzero((both["frame"] == 5777) & (both["person_id"] == 2))[0]
    assert both["score"][i].mean() == pytest.approx(0.013, abs=1e-3)


def test_synthetic_versions_gaps_and_extra_fields():
    frames = pan.face_frames(SYNTH)
    nums = list(frames)
    assert nums[0] == 100 and {104, 105, 111}.isdisjoint(nums)
    versions = {pan.read_face_frame(p)["version"] for p in frames.values()}
    assert versions == {0.5, 0.7}
    f7 = next(pan.read_face_frame(p) for p in frames.values() if pan.read_face_frame(p)["version"] == 0.7)
    assert np.isfinite(f7["univTime"])
    cams = pan.read_calibration(pan.find_calibration(SYNTH), "hd")
    assert all(t == "hd" for t in cams.types)
    assert len(pan.read_calibration(pan.find_calibration(SYNTH))) == len(cams) + 2  # plus a vga and a kinect


def test_image_path():
    assert pan.image_path("00_08", 6577) == "hdImgs/00_08/00_08_00006577.jpg"
    assert pan.image_path("01_02", 3, "vga") == "vgaImgs/01_02/01_02_00000003.jpg"


# ---------------------------------------------------------------- bad files
def _face_doc(n=1):
    return {
        "version": 0.7,
        "univTime": 1.0,
        "people": [
            {
                "id": i,
                "face70": {
                    "landmarks": [float(v) for v in range(210)],
                    "averageScore": [0.5] * 70,
                    "averageReproError": [1.0] * 70,
                    "visibility": [[0]] * 70,
                },
            }
            for i in range(n)
        ],
    }


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text if isinstance(text, str) else json.dumps(text))
    return p


def test_truncated_json(tmp_path):
    p = _write(tmp_path, "faceRecon3D_hd00000001.json", json.dumps(_face_doc())[:300])
    with pytest.raises(HpeError, match=r"faceRecon3D_hd00000001.json: not valid JSON .*truncated"):
        pan.read_face_frame(p)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.pop("people"), "expected an object with a 'people' list"),
        (lambda d: d["people"][0].pop("face70"), r"person 0 \(id 0\): missing key 'face70'"),
        (lambda d: d["people"][0]["face70"].pop("landmarks"), "missing key 'landmarks'"),
        (lambda d: d["people"][0]["face70"].pop("averageScore"), "missing key 'averageScore'"),
        (lambda d: d["people"][0].pop("id"), "person 0: missing key 'id'"),
        (
            lambda d: d["people"][0]["face70"].__setitem__("landmarks", [1.0] * 209),
            "expected 210 landmarks values, got 209",
        ),
        (lambda d: d["people"][0]["face70"].__setitem__("averageScore", "high"), "expected averageScore to be a list"),
        (lambda d: d["people"][1].__setitem__("id", 0), "person ids repeat"),
    ],
)
def test_missing_or_bad_keys(tmp_path, mutate, message):
    doc = _face_doc(2)
    mutate(doc)
    p = _write(tmp_path, "faceRecon3D_hd00000002.json", doc)
    with pytest.raises(HpeError, match=message):
        pan.read_face_frame(p)


def test_nan_and_null_landmarks_parse_as_nan(tmp_path):
    doc = _face_doc()
    doc["people"][0]["face70"]["landmarks"][0] = None
    text = json.dumps(doc).replace("3.0, 4.0", "NaN, 4.0", 1)
    f = pan.read_face_frame(_write(tmp_path, "faceRecon3D_hd00000003.json", text))
    assert np.isnan(f["landmarks"][0, 0, 0]) and np.isnan(f["landmarks"][0, 1, 0])
    assert f["landmarks"][0, 1, 1] == 4.0
    assert np.isnan(f["reproj_error"]).sum() == 0


def test_empty_people_and_missing_reproj(tmp_path):
    f = pan.read_face_frame(_write(tmp_path, "faceRecon3D_hd00000004.json", {"version": 0.5, "people": []}))
    assert f["landmarks"].shape == (0, 70, 3)
    doc = _face_doc()
    del doc["people"][0]["face70"]["averageReproError"]
    f = pan.read_face_frame(_write(tmp_path, "faceRecon3D_hd00000005.json", doc))
    assert np.isnan(f["reproj_error"]).all()


def test_bad_calibration(tmp_path):
    good = {
        "name": "00_00",
        "type": "hd",
        "resolution": [1920, 1080],
        "panel": 0,
        "node": 0,
        "K": [[1000, 0, 960], [0, 1000, 540], [0, 0, 1]],
        "distCoef": [0, 0, 0, 0, 0],
        "R": np.eye(3).tolist(),
        "t": [[0], [0], [0]],
        "someNewField": 3,
    }
    p = _write(tmp_path, "calibration_x.json", {"cameras": [good]})
    assert len(pan.read_calibration(p)) == 1  # unknown fields are ignored
    cases = [
        ({"cameras": [dict(good, K=[[1, 0], [0, 1]])]}, r"camera 0 \(00_00\): expected K with 9 values"),
        ({"cameras": [{k: v for k, v in good.items() if k != "R"}]}, "missing key 'R'"),
        ({"cameras": [dict(good, R=(2 * np.eye(3)).tolist())]}, "expected R to be a rotation"),
        ({"cameras": [dict(good, distCoef=[0.1, 0.2])]}, "expected 5 distCoef values"),
        ({"cameras": [dict(good, t=[[np.nan], [0], [0]])]}, "expected finite"),
        ({"cameras": [dict(good, resolution=[1920])]}, "expected resolution"),
        ({"cams": []}, "expected an object with a 'cameras' list"),
        ({"cameras": []}, "lists no cameras"),
    ]
    for doc, message in cases:
        p = _write(tmp_path, "calibration_x.json", doc)
        with pytest.raises(HpeError, match=message):
            pan.read_calibration(p)
    with pytest.raises(HpeError, match="no such file"):
        pan.read_calibration(tmp_path / "nope.json")
    p = _write(tmp_path, "calibration_x.json", {"cameras": [good]})
    with pytest.raises(HpeError, match="expected a camera name"):
        pan.read_calibration(p, "00_99")


def test_find_calibration_and_face_dir(tmp_path):
    with pytest.raises(HpeError, match="no calibration"):
        pan.find_calibration(tmp_path)
    (tmp_path / "calibration_a.json").write_text("{}")
    assert pan.find_calibration(tmp_path).name == "calibration_a.json"
    (tmp_path / "calibration_b.json").write_text("{}")
    with pytest.raises(HpeError, match="several calibration files"):
        pan.find_calibration(tmp_path)
    with pytest.raises(HpeError, match="no hdFace3d"):
        pan.face_frames(tmp_path)
    (tmp_path / "hdFace3d").mkdir()
    for name in ("faceRecon3D_hd00000007.json", "faceRecon3D_hd00000002.json", "notes.txt", "faceRecon3D_x.json"):
        (tmp_path / "hdFace3d" / name).write_text("{}")
    assert list(pan.face_frames(tmp_path)) == [2, 7]
