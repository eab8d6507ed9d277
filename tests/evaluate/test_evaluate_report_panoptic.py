"""``hpe evaluate --report`` on labels from ``hpe relabel-panoptic`` (real pizza1 frames, hdImgs/hd_00_XX/ layout):
every worst row has its picture, cut around the face box of the 1920x1080 frame with the poses drawn on it,
and ``--protocol directmhp`` picks DirectMHP's v2 scorer for CMU Panoptic."""

import base64
import re
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe

SEQ = Path(__file__).resolve().parents[3] / "shared" / "realdata" / "panoptic_160906_pizza1"
pytestmark = pytest.mark.skipif(not (SEQ / "hdImgs").is_dir(), reason="shared Panoptic sample not available")


def test_panoptic_worst_rows_pictured_around_the_faces(tmp_path):
    labels = tmp_path / "pizza.parquet"
    r = hpe("relabel-panoptic", SEQ, "-o", labels, "--cameras", "00_00,00_08", "--frames", "1147:1148")
    assert r.exit_code == 0, r.output
    t = pd.read_parquet(labels)
    pred = t[["sequence", "camera", "frame", "person_id", "pitch", "yaw", "roll"]].copy()
    pred["yaw"] += 10.0 + 5.0 * np.arange(len(pred))
    p = tmp_path / "pred.csv"
    pred.sample(frac=1.0, random_state=2).to_csv(p, index=False)
    page = tmp_path / "r.html"
    r = hpe(
        "evaluate",
        p,
        labels,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--key",
        "sequence,camera,frame,person_id",
        "--images",
        SEQ,
        "--report",
        page,
        "--worst",
        "5",
        "--protocol",
        "directmhp",
    )
    assert r.exit_code == 0, r.output
    assert "directmhp: GT is CMU Panoptic" in r.output
    text = page.read_text()
    pics = re.findall(r'class="pic" src="data:image/jpeg;base64,([^"]+)"', text)
    assert len(pics) == 5
    for b64 in pics:
        img = cv2.imdecode(np.frombuffer(base64.b64decode(b64), np.uint8), cv2.IMREAD_COLOR)
        assert img is not None and abs(img.shape[1] / img.shape[0] - 16 / 9) > 0.2  # a crop, not the 16:9 frame
        assert (np.abs(img.astype(int) - (0, 0, 255)).max(axis=2) < 60).sum() > 5  # the red axis is drawn
    assert "bbox_x" not in text.split("Worst 5 rows")[1].split("</tr>")[0]  # boxes place pictures, not columns
