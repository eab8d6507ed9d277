"""COCO (DirectMHP schema) and WHENet annotation.txt writers."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli.errors import HpeError
from hpe_cli.io.coco import write_coco
from hpe_cli.io.whenet_txt import read_whenet, write_whenet


def _table(n_lm=3):
    t = pd.DataFrame(
        {
            "image": ["a/img1.png", "b/img2.png", "a/img1.png"],
            "bbox_x": [10.0, 20.0, 300.0],
            "bbox_y": [5.0, 6.0, 7.0],
            "bbox_w": [40.0, 50.0, 60.0],
            "bbox_h": [44.0, 55.0, 66.0],
            "pitch": [1.5, -20.25, 30.0],
            "yaw": [2.5, 150.0, -45.0],
            "roll": [3.5, 10.0, -5.0],
            "extra": ["x", "y", "z"],
        }
    )
    for i in range(n_lm):
        t[f"lm{i}_x"] = [100.0 + i, 200.0 + i, 300.0 + i]
        t[f"lm{i}_y"] = [110.0 + i, 210.0 + i, 310.0 + i]
    return t


def _strict_load(path):
    def no_constant(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=no_constant)


def test_coco_schema(tmp_path):
    t = _table()
    t.loc[1, "lm1_x"] = np.nan  # a missing landmark
    out = tmp_path / "coco.json"
    assert write_coco(t, out, width=3840, height=2160, info={"description": "test"}) == out
    doc = _strict_load(out)
    assert set(doc) >= {"images", "annotations", "categories", "info"}
    assert doc["categories"] == [{"supercategory": "person", "id": 1, "name": "person"}]
    assert doc["info"] == {"description": "test"}
    assert doc["images"] == [
        {"file_name": "a/img1.png", "height": 2160, "width": 3840, "id": 1},
        {"file_name": "b/img2.png", "height": 2160, "width": 3840, "id": 2},
    ]
    anns = doc["annotations"]
    assert [a["id"] for a in anns] == [1, 2, 3]
    assert [a["image_id"] for a in anns] == [1, 2, 1]
    for a in anns:
        assert set(a) == {
            "image_id",
            "id",
            "category_id",
            "bbox",
            "euler_angles",
            "face2d_pts",
            "area",
            "iscrowd",
            "segmentation",
        }
        assert a["category_id"] == 1 and a["iscrowd"] == 0 and a["segmentation"] == []
    a = anns[1]
    assert a["bbox"] == [20.0, 6.0, 50.0, 55.0]
    assert a["euler_angles"] == [-20.25, 150.0, 10.0]  # pitch, yaw, roll
    assert a["area"] == pytest.approx(50.0 * 55.0)
    assert a["face2d_pts"] == [[200.0, -1.0, 202.0], [210.0, -1.0, 212.0]]  # [[x...], [y...]], -1 = missing
    assert anns[0]["face2d_pts"] == [[100.0, 101.0, 102.0], [110.0, 111.0, 112.0]]


def test_coco_sizes_from_columns(tmp_path):
    t = _table(0)
    t["image_width"] = [1280, 640, 1280]
    t["image_height"] = [720, 480, 720]
    out = tmp_path / "c.json"
    write_coco(t, out)
    doc = _strict_load(out)
    assert [(i["width"], i["height"]) for i in doc["images"]] == [(1280, 720), (640, 480)]
    assert all(a["face2d_pts"] == [] for a in doc["annotations"])


def test_coco_inconsistent_or_missing_size(tmp_path):
    t = _table(0)
    with pytest.raises(HpeError, match="image_width"):
        write_coco(t, tmp_path / "c.json")
    t["image_width"] = [1280, 640, 1000]
    t["image_height"] = [720, 480, 720]
    with pytest.raises(HpeError, match="one image_width per image"):
        write_coco(t, tmp_path / "c.json")
    assert list(tmp_path.iterdir()) == []


def test_coco_refuses_overwrite_and_is_atomic(tmp_path):
    out = tmp_path / "c.json"
    out.write_text("precious")
    with pytest.raises(HpeError, match="already exists"):
        write_coco(_table(), out, width=10, height=10)
    assert out.read_text() == "precious"
    bad = _table()
    bad.loc[2, "yaw"] = np.nan
    with pytest.raises(HpeError, match="row 2.*yaw"):
        write_coco(bad, out, overwrite=True, width=10, height=10)
    assert out.read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.json"]  # no temp file left
    write_coco(_table(), out, overwrite=True, width=10, height=10)
    assert len(_strict_load(out)["annotations"]) == 3


def test_coco_missing_columns(tmp_path):
    with pytest.raises(HpeError, match="bbox_w"):
        write_coco(_table().drop(columns=["bbox_w"]), tmp_path / "c.json", width=1, height=1)


def test_coco_empty_table_is_valid(tmp_path):
    out = tmp_path / "c.json"
    write_coco(_table().iloc[:0], out, width=1, height=1)
    doc = _strict_load(out)
    assert doc["images"] == [] and doc["annotations"] == []


# ---------------------------------------------------------------------- WHENet
def _whenet_line(image, yaw, pitch, roll):
    """WHENet prepare_images.py's own line: path, then str() of yaw, pitch, roll."""
    return image + "," + str(yaw) + "," + str(pitch) + "," + str(roll) + "\n"


def test_whenet_lines_match_whenets_format(tmp_path):
    t = _table()
    out = tmp_path / "annotation.txt"
    write_whenet(t, out)
    expected = "".join(_whenet_line(i, y, p, r) for i, p, y, r in zip(t["image"], t["pitch"], t["yaw"], t["roll"]))
    assert out.read_text(encoding="utf-8") == expected
    assert out.read_text().splitlines()[1] == "b/img2.png,150.0,-20.25,10.0"  # yaw first


def test_whenet_refuses_overwrite_and_bad_rows(tmp_path):
    out = tmp_path / "annotation.txt"
    out.write_text("old\n")
    with pytest.raises(HpeError, match="already exists"):
        write_whenet(_table(), out)
    t = _table()
    t.loc[0, "image"] = "a,b.png"
    with pytest.raises(HpeError, match="row 0.*commas"):
        write_whenet(t, out, overwrite=True)
    t = _table()
    t.loc[1, "roll"] = np.inf
    with pytest.raises(HpeError, match="row 1.*roll"):
        write_whenet(t, out, overwrite=True)
    assert out.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["annotation.txt"]


def test_read_whenet_rejects_garbage(tmp_path):
    f = tmp_path / "a.txt"
    f.write_text("x.jpg,1,2,3\nbroken line\n")
    with pytest.raises(HpeError, match="line 2"):
        read_whenet(f)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-180, 180), st.floats(-90, 90), st.floats(-90, 90)), min_size=1, max_size=8))
def test_whenet_roundtrip_exact(tmp_path_factory, rows):
    a = np.asarray(rows)
    t = pd.DataFrame(
        {
            "image": [f"s/{k:02d}_0_{k:08d}.jpg" for k in range(len(a))],
            "yaw": a[:, 0],
            "pitch": a[:, 1],
            "roll": a[:, 2],
        }
    )
    out = tmp_path_factory.mktemp("w") / "annotation.txt"
    write_whenet(t, out)
    back = read_whenet(out)
    assert list(back["image"]) == list(t["image"])
    for c in ("pitch", "yaw", "roll"):
        assert np.array_equal(back[c].to_numpy(), t[c].to_numpy())  # bit-exact
    assert all(math.isfinite(v) for v in back["yaw"])
