"""``hpe export`` from a Panoptic video smaller than the calibration: the error and each reject name the video
that was read and the frame, not only the table's hdImgs/... name (no such file was read) (issue 35)."""

from __future__ import annotations

import sys
import types

import numpy as np
import pandas as pd

from conftest import hpe


def _video_table(tmp_path, monkeypatch, ok_row=True):
    """Two heads of hdImgs/00_03 frames 3 and 4 read from hdVideos/hd_00_03.mp4 through a stand-in VideoFrames
    giving 1280x720 frames under 1920x1080 labels, and (``ok_row``) one head of a JPEG that exports."""

    class VideoFrames:  # a stand-in for datasets.panoptic_video.VideoFrames giving 1280x720 frames
        def __init__(self, path):
            self.path = path

        def read(self, frames):
            for f in frames:
                yield f, np.full((720, 1280, 3), 80, np.uint8), ""

    mod = types.ModuleType("hpe_cli.datasets.panoptic_video")
    mod.VideoFrames = VideoFrames
    monkeypatch.setitem(sys.modules, "hpe_cli.datasets.panoptic_video", mod)
    rows = [
        {
            "image": f"hdImgs/00_03/00_03_{f:08d}.jpg",
            "sequence": "",
            "camera": "00_03",
            "frame": f,
            "person_id": 1,
            "image_width": 1920,
            "image_height": 1080,
            "bbox_x": 10.0,
            "bbox_y": 10.0,
            "bbox_w": 40.0,
            "bbox_h": 40.0,
            "pitch": 0.0,
            "yaw": 5.0,
            "roll": 0.0,
        }
        for f in (3, 4)
    ]
    if ok_row:
        import cv2

        (tmp_path / "img").mkdir()
        cv2.imwrite(str(tmp_path / "img" / "ok.jpg"), np.full((1080, 1920, 3), 90, np.uint8))
        rows.append({**rows[0], "image": "img/ok.jpg", "camera": "", "frame": 9})  # one head that exports
    path = tmp_path / "t.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    (tmp_path / "hdVideos").mkdir()
    (tmp_path / "hdVideos" / "hd_00_03.mp4").write_bytes(b"")
    return path


def test_error_and_rejects_name_the_video_and_frame(tmp_path, monkeypatch):
    path = _video_table(tmp_path, monkeypatch)
    video = tmp_path / "hdVideos" / "hd_00_03.mp4"
    res = hpe("export", path, "-o", tmp_path / "out", "--layout", "whenet")
    assert res.exit_code == 1
    assert f"(video {video} frame 3)" in res.output and "image size 1280x720 differs" in res.output, res.output
    res = hpe("export", path, "-o", tmp_path / "out", "--layout", "whenet", "--rejects", tmp_path / "r.csv")
    assert res.exit_code == 0, res.output
    reasons = pd.read_csv(tmp_path / "r.csv")["reason"].tolist()
    assert len(reasons) == 2
    for f, reason in zip((3, 4), reasons):
        assert reason.endswith(f"(video {video} frame {f})"), reason
