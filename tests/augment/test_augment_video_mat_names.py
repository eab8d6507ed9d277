"""hpe augment: video frames decoded once per video, in frame order (the reader draw uses); a .mat folder's bad
rows named by their .mat file, in messages and in the rejects file."""

import shutil

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.datasets import panoptic_video


def _video(path, n, w=64, h=48):
    path.parent.mkdir(parents=True, exist_ok=True)
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, (w, h))
    for k in range(n):
        vw.write(np.full((h, w, 3), 20 * k, np.uint8))
    vw.release()


def test_video_frames_decoded_once_per_video_in_order(tmp_path, monkeypatch):
    """Rows of two videos, shuffled: each video is opened once and its frames come front to back; every output
    image is the right frame (grey level 20 * frame) flipped."""
    for cam in ("00_03", "00_07"):
        _video(tmp_path / "seq" / "hdVideos" / f"hd_{cam}.mp4", n=8)
    rows = [(cam, f) for cam in ("00_03", "00_07") for f in (1, 3, 6, 7)]
    rng = np.random.default_rng(0)
    rows = [rows[k] for k in rng.permutation(len(rows))]
    pd.DataFrame(
        {
            "image": [f"hdImgs/{c}/{c}_{f:08d}.jpg" for c, f in rows],
            "camera": [c for c, _ in rows],
            "frame": [f for _, f in rows],
            "pitch": 0.0,
            "yaw": 10.0,
            "roll": 0.0,
            "tdx": 10.0,
            "tdy": 20.0,
        }
    ).to_parquet(tmp_path / "l.parquet")
    calls = []
    real = panoptic_video.VideoFrames.read

    def spy(self, frames):
        frames = list(frames)
        calls.append((self.path.name, frames))
        yield from real(self, frames)

    monkeypatch.setattr(panoptic_video.VideoFrames, "read", spy)
    res = hpe(
        "augment",
        tmp_path / "l.parquet",
        "-o",
        tmp_path / "o.parquet",
        "--hflip",
        "--images",
        tmp_path / "seq",
        "--out-images",
        tmp_path / "out",
    )
    assert res.exit_code == 0, res.output
    assert sorted(calls) == [("hd_00_03.mp4", [1, 3, 6, 7]), ("hd_00_07.mp4", [1, 3, 6, 7])]
    for c, f in rows:
        img = cv2.imread(str(tmp_path / "out" / "hdImgs" / c / f"{c}_{f:08d}.jpg"))
        assert img.shape == (48, 64, 3) and abs(img.mean() - 20 * f) < 6
    out = pd.read_parquet(tmp_path / "o.parquet")
    assert np.allclose(out["tdx"], 63 - 10.0)  # W - 1 - x


@pytest.fixture
def mat3(realdata, tmp_path):
    """Three AFLW2000 .mat files, the third without its image."""
    AFLW = realdata / "aflw2000_prnet"
    d = tmp_path / "m"
    d.mkdir()
    for stem in ("image00050", "image00081"):
        shutil.copy(f"{AFLW}/{stem}.mat", d)
        shutil.copy(f"{AFLW}/{stem}.jpg", d)
    shutil.copy(f"{AFLW}/image00251.mat", d)
    return d


def test_mat_folder_rows_named_by_their_mat_file(mat3, tmp_path):
    res = hpe("augment", mat3, "-o", tmp_path / "a.parquet", "--hflip", "--out-images", tmp_path / "o")
    assert res.exit_code == 1
    line = res.output.strip().splitlines()[-1]
    assert line.startswith(f"Error: {mat3 / 'image00251.mat'}: image not found"), line
    assert "row " not in line
    res = hpe(
        "augment",
        mat3,
        "-o",
        tmp_path / "a.parquet",
        "--hflip",
        "--out-images",
        tmp_path / "o",
        "--rejects",
        tmp_path / "rej.csv",
    )
    assert res.exit_code == 0, res.output
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert rej["file"].tolist() == [str(mat3 / "image00251.mat")] and "row" not in rej.columns
    assert rej["reason"][0].startswith("image not found")
    assert len(pd.read_parquet(tmp_path / "a.parquet")) == 2


def test_mat_folder_size_disagreement_named_by_mat_file(mat3, tmp_path):
    (mat3 / "image00251.mat").unlink()
    res = hpe(
        "augment",
        mat3,
        "-o",
        tmp_path / "a.parquet",
        "--hflip",
        "--image-size",
        400,
        450,
        "--images",
        mat3,
        "--rejects",
        tmp_path / "rej.parquet",
    )
    assert res.exit_code == 1
    line = res.output.strip().splitlines()[-1]
    assert f"({mat3 / 'image00050.mat'}: image size: the image is 450x450, --image-size says 400x450)" in line
    assert not (tmp_path / "a.parquet").exists()
    assert (tmp_path / "rej.parquet").exists()  # every row rejected: the rejects file still says why (issue 35)


def test_draw_mat_folder_rejects_named_by_mat_file(mat3, tmp_path):
    res = hpe("draw", mat3, "-o", tmp_path / "d", "--rejects", tmp_path / "rej.csv")
    assert res.exit_code == 0, res.output
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert rej["file"].tolist() == [str(mat3 / "image00251.mat")] and "row" not in rej.columns


def test_mat_folder_images_give_sizes_without_images_option(mat3, tmp_path):
    """A .mat folder's own images check --image-size even without --images; a .mat without its image then needs
    --image-size (no reject for the missing picture itself: no image is written)."""
    res = hpe("augment", mat3, "-o", tmp_path / "a.parquet", "--hflip", "--image-size", 400, 450)
    assert res.exit_code == 1 and "image size: the image is 450x450, --image-size says 400x450" in res.output
    assert f"{mat3 / 'image00050.mat'}: " in res.output
    res = hpe("augment", mat3, "-o", tmp_path / "b.parquet", "--hflip", "--image-size", 450, 450)
    assert res.exit_code == 0, res.output
    assert len(pd.read_parquet(tmp_path / "b.parquet")) == 3
