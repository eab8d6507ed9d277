"""``hpe export AFLW2000/ ...`` with a broken image: zero-byte, truncated, text instead of JPEG, missing.

Without ``--rejects``: one error line naming the ``.mat`` label and the image, exit 1, nothing written, inputs
unchanged. With ``--rejects``: the head is a reject naming the image and the reason, the rest is exported.
Never ``internal error`` (was ``invalid literal for int() ... 'image00081.mat'`` and an OpenCV assertion).
"""

from __future__ import annotations

import shutil

import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.io.export import LAYOUTS as EXPORT_LAYOUTS

from .conftest import AFLW, TEMP_MARK, check_failed, temp_files, tree

FAULTS = {
    "zero-byte": lambda p: p.write_bytes(b""),
    "truncated": lambda p: p.write_bytes(p.read_bytes()[: int(p.stat().st_size * 0.7)]),
    "truncated-header": lambda p: p.write_bytes(p.read_bytes()[:600]),
    "text": lambda p: p.write_text("this is not a JPEG\n"),
    "png-named-jpg": None,  # a valid image of another format under a .jpg name is fine (decoded by content)
    "missing": lambda p: p.unlink(),
}
REASON = {
    "zero-byte": "unreadable image (empty file)",
    "truncated": "truncated JPEG",
    "text": "unreadable image",
    "truncated-header": "unreadable image",
    "missing": "no image (file not found)",
}
LAYOUTS = list(EXPORT_LAYOUTS)


def broken_copy(tmp_path, fault):
    src = tmp_path / "AFLW2000"
    shutil.copytree(AFLW, src)
    victim = sorted(src.glob("*.jpg"))[1]
    if fault == "png-named-jpg":
        import cv2

        cv2.imwrite(str(victim.with_suffix(".png")), cv2.imread(str(victim)))
        victim.with_suffix(".png").replace(victim)
    else:
        FAULTS[fault](victim)
    return src, victim


def layout_args(layout):
    return ["--layout", layout] + (["--split", "image:train=0.5,val=0.5"] if layout == "directmhp" else [])


@pytest.mark.skipif(not AFLW.exists(), reason="no AFLW2000 sample")
@pytest.mark.parametrize("fault", sorted(f for f in FAULTS if f != "png-named-jpg"))
@pytest.mark.parametrize("layout", LAYOUTS)
def test_broken_image_without_rejects_is_one_line(tmp_path, fault, layout):
    src, victim = broken_copy(tmp_path, fault)
    before = tree(src)
    out = tmp_path / "out"
    res = hpe("export", src, "-o", out, *layout_args(layout))
    line = check_failed(res, must_name=victim.name)
    assert f"{victim.with_suffix('.mat')}" in line and REASON[fault] in line  # the label file and the image
    assert not out.exists() and not temp_files(tmp_path) and tree(src) == before


@pytest.mark.skipif(not AFLW.exists(), reason="no AFLW2000 sample")
@pytest.mark.parametrize("fault", sorted(f for f in FAULTS if f != "png-named-jpg"))
@pytest.mark.parametrize("layout", LAYOUTS)
def test_broken_image_with_rejects_is_a_reject(tmp_path, fault, layout):
    src, victim = broken_copy(tmp_path, fault)
    out, rej = tmp_path / "out", tmp_path / "rej.csv"
    res = hpe("export", src, "-o", out, "--rejects", rej, "-q", *layout_args(layout))
    assert res.exit_code == 0, res.output
    assert "internal error" not in res.output and "Traceback" not in res.output
    r = pd.read_csv(rej)
    assert len(r) == 1 and r["image"].iloc[0] == victim.name and r["row"].iloc[0] == victim.with_suffix(".mat").name
    assert r["reason"].iloc[0].startswith(REASON[fault]) or REASON[fault] in r["reason"].iloc[0]
    n = len(list(src.glob("*.mat")))
    import json

    assert json.loads((out / "export.json").read_text())["exported"] == n - 1
    assert not [p for p in out.rglob("*") if p.name.startswith(TEMP_MARK)]


@pytest.mark.skipif(not AFLW.exists(), reason="no AFLW2000 sample")
def test_every_image_broken_exits_1(tmp_path):
    src = tmp_path / "AFLW2000"
    shutil.copytree(AFLW, src)
    for p in src.glob("*.jpg"):
        p.write_bytes(b"")
    res = hpe("export", src, "-o", tmp_path / "out", "--layout", "whenet", "--rejects", tmp_path / "rej.csv")
    check_failed(res)
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(not AFLW.exists(), reason="no AFLW2000 sample")
def test_png_under_a_jpg_name_is_exported(tmp_path):
    src, _ = broken_copy(tmp_path, "png-named-jpg")
    res = hpe("export", src, "-o", tmp_path / "out", "--layout", "whenet", "-q")
    assert res.exit_code == 0, res.output


def _sized_table(tmp_path, width, height):
    import cv2
    import numpy as np

    (tmp_path / "img").mkdir()
    cv2.imwrite(str(tmp_path / "img" / "a.jpg"), np.full((720, 1280, 3), 90, np.uint8))
    cv2.imwrite(str(tmp_path / "img" / "b.jpg"), np.full((1080, 1920, 3), 90, np.uint8))
    rows = [
        {
            "image": f"img/{n}.jpg",
            "image_width": width,
            "image_height": height,
            "bbox_x": 100.0,
            "bbox_y": 100.0,
            "bbox_w": 80.0,
            "bbox_h": 90.0,
            "pitch": 1.0,
            "yaw": 2.0,
            "roll": 3.0,
        }
        for n in "ab"
    ]
    path = tmp_path / "t.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    return path


def test_image_size_differs_from_the_labels(tmp_path):
    """A frame whose size is not the labels' image_width x image_height (a 1280x720 video or image for a
    1920x1080 calibration) is refused: its boxes would be cut from the wrong pixels."""
    path = _sized_table(tmp_path, 1920, 1080)
    res = hpe("export", path, "-o", tmp_path / "out", "--layout", "whenet")
    line = check_failed(res, must_name=str(path))
    assert "line 2" in line and "image size 1280x720 differs" in line and "1920x1080" in line  # CSV: line 2
    assert not (tmp_path / "out").exists()
    res = hpe("export", path, "-o", tmp_path / "out", "--layout", "whenet", "--rejects", tmp_path / "r.csv", "-q")
    assert res.exit_code == 0, res.output
    r = pd.read_csv(tmp_path / "r.csv")
    assert r["image"].tolist() == ["img/a.jpg"] and r["reason"].iloc[0].startswith("image size 1280x720")


def test_video_frames_smaller_than_the_calibration(tmp_path, monkeypatch):
    """hdVideos read through pan's VideoFrames (a stand-in giving 1280x720 frames) for 1920x1080 labels."""
    from .test_export_video_names import _video_table

    path = _video_table(tmp_path, monkeypatch, ok_row=False)
    res = hpe("export", path, "-o", tmp_path / "out", "--layout", "whenet", "--rejects", tmp_path / "r.csv")
    check_failed(res)  # every head rejected: nothing written, exit 1
    assert "image size 1280x720 differs" in res.output and not (tmp_path / "out").exists()
