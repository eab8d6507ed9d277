"""hpe audit --plots with images: the page shows the first flagged rows of each check drawn on their images and
links to the PNGs; checked on the real AFLW2000 sample, in headless chromium when it is installed."""

import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe


class _Refs(HTMLParser):
    def __init__(self):
        super().__init__()
        self.src, self.href, self.captions, self._cap = [], [], [], False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.src.append(a["src"])
        if tag == "a" and not a["href"].startswith("#"):
            self.href.append(a["href"])
        self._cap = tag == "figcaption"

    def handle_data(self, data):
        if self._cap:
            self.captions.append(data)
            self._cap = False


def _refs(page):
    p = _Refs()
    p.feed(page.read_text(encoding="utf-8"))
    return p


def test_aflw2000_page_shows_flagged_rows_drawn(realdata, tmp_path):
    aflw = realdata / "aflw2000_prnet"
    out = tmp_path / "plots"
    # within 75 deg of the lock: the rows with |pitch| above 15 deg are near_gimbal
    res = hpe("audit", aflw, "--plots", out, "--gimbal-tol", 75)
    assert res.exit_code == 0, res.output
    page = out / "index.html"
    refs = _refs(page)
    pics = [s for s in refs.src if s.startswith("pictures/")]
    assert len(pics) == 3 and sorted(refs.href) == sorted(pics)  # each picture links to its PNG
    for s in refs.src:  # every image the page references exists and is a picture
        img = cv2.imread(str(out / s))
        assert img is not None and img.size, s
    caps = [c for c in refs.captions if c.startswith("near_gimbal: ")]
    assert len(caps) == 3 and all(re.fullmatch(r"near_gimbal: image\d{5}\.mat", c) for c in caps), caps
    assert '<h3 id="check-near_gimbal">near_gimbal</h3>' in page.read_text()
    # each picture is its image (450 x 450, shrunk to fit the page) with the red, green and blue axes drawn
    for s, cap in zip(pics, caps):
        img = cv2.imread(str(out / s)).astype(int)
        orig = cv2.imread(str(aflw / cap.split(": ")[1].replace(".mat", ".jpg")))
        assert img.shape[0] == img.shape[1] <= orig.shape[0]
        for colour in ((0, 0, 255), (0, 255, 0), (255, 0, 0)):
            assert (np.abs(img - colour).max(axis=2) < 40).sum() > 20, (s, colour)
    if shutil.which("chromium") is None:
        pytest.skip("chromium not installed: the browser check is skipped")
    shot = tmp_path / "shot.png"
    subprocess.run(
        [
            "chromium",
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--no-first-run",
            f"--screenshot={shot}",
            "--window-size=1200,2600",
            page.as_uri(),
        ],
        capture_output=True,
        timeout=120,
        check=False,
    )
    img = cv2.imread(str(shot))
    assert img is not None
    bottom = img[int(img.shape[0] * 0.75) :].astype(int)  # the gallery: photos, not a white page
    colourful = (bottom.max(axis=2) - bottom.min(axis=2)) > 40
    assert colourful.mean() > 0.05


def test_missing_images_listed_and_no_images_no_section(tmp_path):
    t = pd.DataFrame({"image": ["a.jpg", "b.jpg"], "pitch": [0.0, 0.0], "yaw": [0.0, 89.9], "roll": [0.0, 0.0]})
    t.to_csv(tmp_path / "l.csv", index=False)
    res = hpe("audit", tmp_path / "l.csv", "--plots", tmp_path / "p")
    assert res.exit_code == 0, res.output
    page = (tmp_path / "p" / "index.html").read_text()
    assert "Not drawn" in page and "line 3: image not found" in page and not (tmp_path / "p" / "pictures").exists()
    t.drop(columns="image").to_parquet(tmp_path / "n.parquet")
    res = hpe("audit", tmp_path / "n.parquet", "--plots", tmp_path / "q")
    assert res.exit_code == 0 and "Flagged rows" not in (tmp_path / "q" / "index.html").read_text()
    assert Path(tmp_path / "q" / "yaw_hist.png").is_file()


def test_panoptic_page_pictures_around_the_faces(realdata, tmp_path):
    """relabel-panoptic -> audit --plots --images on the real pizza1 folder (hdImgs/hd_00_XX/ layout): each
    picture is the part of the 1920x1080 frame around the face's box, with the axes drawn from its centre."""
    seq = realdata / "panoptic_160906_pizza1"
    labels = tmp_path / "pizza.parquet"
    res = hpe("relabel-panoptic", seq, "-o", labels, "--cameras", "00_00,00_08", "--frames", "1147:1148")
    assert res.exit_code == 0, res.output
    out = tmp_path / "plots"
    res = hpe("audit", labels, "--plots", out, "--images", seq, "--gimbal-tol", 89)  # every row is near_gimbal
    assert res.exit_code == 0, res.output
    refs = _refs(out / "index.html")
    caps = [c for c in refs.captions if c.startswith("near_gimbal: ")]
    t = pd.read_parquet(labels)
    assert caps == [f"near_gimbal: row {k + 1} ({t['image'][k]})" for k in range(3)]
    for k, s in enumerate(p for p in refs.src if p.startswith("pictures/")):
        img = cv2.imread(str(out / s))
        side = max(3 * t["bbox_h"][k] / 2, 80) * 2
        assert img is not None and max(img.shape[:2]) <= min(side + 2, 480)
        assert (np.abs(img.astype(int) - (0, 0, 255)).max(axis=2) < 40).sum() > 5  # the red axis is there
