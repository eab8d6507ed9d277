"""``hpe view`` on a synthetic CMU Panoptic release whose pictures are only videos (``hdVideos/hd_00_XX.mp4``, no
extracted ``hdImgs``): the thumbnails and full frames are the video frames' pixels (each frame a different
texture, so the wrong frame cannot pass), each video is decoded once, front to back, and a frame past the end is a
reject with its reason."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pandas as pd

from conftest import hpe
from hpe_cli.datasets import panoptic_video

from .conftest import detail_chunk, page_data

W, H, FRAMES = 160, 120, 12
CAMS = ("00_03", "00_07")


def _texture(rng):
    img = cv2.GaussianBlur(rng.uniform(0, 255, (H, W, 3)), (0, 0), 2.5)
    return ((img - img.min()) / (img.max() - img.min()) * 255).astype(np.uint8)


def _release(root):
    """Two HD videos of FRAMES frames; and the frames as OpenCV decodes them, read independently (in order)."""
    rng = np.random.default_rng(3)
    (root / "hdVideos").mkdir(parents=True)
    decoded = {}
    for cam in CAMS:
        path = root / "hdVideos" / f"hd_{cam}.mp4"
        vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, (W, H))
        for _ in range(FRAMES):
            vw.write(_texture(rng))
        vw.release()
        cap = cv2.VideoCapture(str(path))
        frames = []
        while True:
            ok, img = cap.read()
            if not ok:
                break
            frames.append(img)
        cap.release()
        assert len(frames) == FRAMES
        decoded[cam] = frames
    return decoded


def _crop(img, box):
    """hpe view's documented crop: the square 1.6 x the box's longer side around its centre, resized to 128."""
    x, y, w, h = box
    side = 1.6 * max(w, h)
    x0, y0, s = int(np.floor(x + w / 2 - side / 2)), int(np.floor(y + h / 2 - side / 2)), int(np.ceil(side))
    pad = cv2.copyMakeBorder(img, s, s, s, s, cv2.BORDER_CONSTANT, value=(48, 48, 48))
    return cv2.resize(pad[y0 + s : y0 + 2 * s, x0 + s : x0 + 2 * s], (128, 128), interpolation=cv2.INTER_LINEAR)


def test_thumbnails_are_the_video_frames_pixels_each_video_decoded_once(tmp_path, monkeypatch):
    root = tmp_path / "160906_synthetic"
    decoded = _release(root)
    rng = np.random.default_rng(5)
    rows = []
    for _ in range(40):  # frames in no order, several heads per frame, both cameras
        cam, fr = CAMS[rng.integers(0, 2)], int(rng.integers(0, FRAMES))
        w = float(rng.uniform(40, 70))
        rows.append({"camera": cam, "frame": fr, "image": f"hdImgs/{cam}/{cam}_{fr:08d}.jpg", "person_id": len(rows),
                     "pitch": float(rng.uniform(-30, 30)), "yaw": float(rng.uniform(-60, 60)), "roll": 0.0,
                     "bbox_x": float(rng.uniform(10, W - 80)), "bbox_y": float(rng.uniform(5, H - 75)),
                     "bbox_w": w, "bbox_h": w})  # fmt: skip
    rows.append({**rows[0], "camera": CAMS[0], "frame": FRAMES + 5, "image": f"hdImgs/{CAMS[0]}/{CAMS[0]}_{FRAMES + 5:08d}.jpg",
                 "person_id": 99})  # fmt: skip  # past the end of the video
    labels = tmp_path / "labels.csv"
    pd.DataFrame(rows).to_csv(labels, index=False)

    calls = []
    real = panoptic_video.VideoFrames.read

    def spy(self, frame_numbers):
        frame_numbers = list(frame_numbers)
        calls.append((self.path.name, frame_numbers))
        return real(self, frame_numbers)

    monkeypatch.setattr(panoptic_video.VideoFrames, "read", spy)
    page = tmp_path / "page"
    r = hpe("view", labels, "-o", page, "--images", root, "--rejects", tmp_path / "rej.csv", "--threads", "2")
    assert r.exit_code == 0, r.output
    assert "40 of 41 rows shown" in r.output, r.output

    # each video decoded once, its frames asked for in ascending order
    by_video = {}
    for name, frs in calls:
        by_video.setdefault(name, []).append(frs)
    used = {c: sorted({x["frame"] for x in rows if x["camera"] == c}) for c in CAMS}  # 00_03: and the one past the end
    assert by_video == {f"hd_{c}.mp4": [used[c]] for c in CAMS}, calls

    d = page_data(page)
    chunk = detail_chunk(page, 0)
    for i, row in enumerate(rows[:-1]):
        frames = decoded[row["camera"]]
        got = cv2.imread(str(page / "thumbs" / d["thumb"][i])).astype(int)
        box = (row["bbox_x"], row["bbox_y"], row["bbox_w"], row["bbox_h"])
        diffs = [np.median(np.abs(got - _crop(f, box).astype(int)).max(axis=2)) for f in frames]
        # this row's frame, with JPEG's loss and the pose lines; every other frame is far away
        assert int(np.argmin(diffs)) == row["frame"] and diffs[row["frame"]] < 14, (i, diffs)
        assert sorted(diffs)[1] > 2 * diffs[row["frame"]] + 10, (i, diffs)
        # the detail view's full frame: the whole video frame (smaller than 960 px: kept at its size)
        im = d["images"][d["img"][i]]
        assert (im["w"], im["h"]) == (W, H)
        full = cv2.imread(str(page / "frames" / im["f"])).astype(int)
        assert full.shape == (H, W, 3)
        fd = [np.median(np.abs(full - f.astype(int)).max(axis=2)) for f in frames]
        assert int(np.argmin(fd)) == row["frame"] and fd[row["frame"]] < 14 and sorted(fd)[1] > 2 * min(fd), fd
        assert chunk["values"]["frame"][i] == row["frame"]
    assert len(d["images"]) == len({(x["camera"], x["frame"]) for x in rows})
    # the frame past the end: a reject naming the video and its length, and in the page without a picture
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert len(rej) == 1 and rej["person_id"].iloc[0] == 99
    assert (
        f"hd_{CAMS[0]}.mp4" in rej["reason"].iloc[0]
        and f"past the end of the video ({FRAMES} frames)" in (rej["reason"].iloc[0])
    )
    assert d["thumb"][-1] is None
    status = d["cat"]["status"]
    assert "past the end" in status["values"][status["codes"][-1]]
    json.dumps(d)  # plain data
