"""relabel-panoptic -> augment (crop, hflip) with the real pizza1 frames -> draw (no --image-size: the sizes come
from image_width/image_height and the images). Oracles: the crop is slicing, the flip is cv2.flip; landmarks and
boxes move by the same pixels; the drawn lines start at the moved box centres."""

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.geometry.landmark_schemes import flip_permutation

CROP = (300, 150, 1300, 800)


@pytest.fixture
def pizza(realdata, tmp_path):
    seq = realdata / "panoptic_160906_pizza1"
    out = tmp_path / "labels.parquet"
    res = hpe("relabel-panoptic", seq, "-o", out, "--cameras", "00_00,00_08", "--frames", "1147:1148")
    assert res.exit_code == 0, res.output
    return seq, out


@pytest.mark.parametrize("op", ["crop", "hflip"])
def test_relabel_augment_draw(pizza, tmp_path, op):
    seq, labels = pizza
    args = ["--crop", *CROP] if op == "crop" else ["--hflip"]
    res = hpe(
        "augment", labels, "-o", tmp_path / "aug.parquet", *args, "--images", seq, "--out-images", tmp_path / "imgs"
    )
    assert res.exit_code == 0, res.output
    a, b = pd.read_parquet(labels), pd.read_parquet(tmp_path / "aug.parquet")
    assert len(a) == len(b) and (b["image"] == a["image"]).all()
    x, y, w, h = CROP
    if op == "crop":
        assert (b.image_width == w).all() and (b.image_height == h).all()
        assert np.allclose(b.lm5_x, a.lm5_x - x) and np.allclose(b.bbox_y, a.bbox_y - y)
        assert np.allclose(b[["pitch", "yaw", "roll"]], a[["pitch", "yaw", "roll"]])
    else:
        perm = flip_permutation("face70")
        for i in (0, 36, 69):
            assert np.allclose(b[f"lm{i}_x"], 1919 - a[f"lm{perm[i]}_x"], equal_nan=True)
        assert np.allclose(b.bbox_x, 1919 - a.bbox_x - a.bbox_w)
    for name in a["image"].unique():
        cam = name.split("/")[1]
        src = cv2.imread(str(seq / "hdImgs" / f"hd_{cam}" / "00001147.jpg"))
        ref = src[y : y + h, x : x + w] if op == "crop" else cv2.flip(src, 1)
        got = cv2.imread(str(tmp_path / "imgs" / name))
        assert got.shape == ref.shape and np.abs(got.astype(int) - ref.astype(int)).mean() < 2.5
    res = hpe(
        "draw", tmp_path / "aug.parquet", "-o", tmp_path / "drawn", "--images", tmp_path / "imgs", "--thickness", "4"
    )
    assert res.exit_code == 0, res.output
    checked = 0
    for _, r in b.iterrows():
        u, v = r.bbox_x + r.bbox_w / 2, r.bbox_y + r.bbox_h / 2
        W, H = (w, h) if op == "crop" else (1920, 1080)
        if not (5 <= u < W - 5 and 5 <= v < H - 5):
            continue  # this face is outside the crop
        before = cv2.imread(str(tmp_path / "imgs" / r.image)).astype(int)
        after = cv2.imread(str(tmp_path / "drawn" / r.image)).astype(int)
        iu, iv = round(u), round(v)
        assert np.abs(after[iv - 2 : iv + 3, iu - 2 : iu + 3] - before[iv - 2 : iv + 3, iu - 2 : iu + 3]).max() > 60
        checked += 1
    assert checked >= 3
