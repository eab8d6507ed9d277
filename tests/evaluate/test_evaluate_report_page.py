"""``hpe evaluate --report page.html`` on the AFLW2000 sample with shuffled predictions, opened in headless Chromium.

The page must show every protocol with its source, the ``--by`` and
``--yaw-bins`` tables, the row counts, units per column (DAD-3DHeads'
Frobenius unitless), the plots and the worst rows, each with its picture
(ground truth and prediction drawn on the face by ``hpe draw``'s
``render_worst``, the pictures ``draw_worst`` writes, embedded in the page).
"""

import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from view.conftest import browser as _browser

from conftest import hpe

SHARED = Path(__file__).resolve().parents[3] / "shared"
AFLW = SHARED / "realdata" / "aflw2000_prnet"
PRED = SHARED / "golden" / "evaluate" / "aflw16m" / "pred.csv"
pytestmark = pytest.mark.skipif(not (AFLW.is_dir() and PRED.is_file()), reason="shared data not available")


def _make_page(tmp_path, worst=6):
    pred = tmp_path / "shuffled.csv"
    pd.read_csv(PRED).sample(frac=1.0, random_state=11).to_csv(pred, index=False)
    page = tmp_path / "page.html"
    r = hpe(
        "evaluate",
        pred,
        AFLW,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--report",
        page,
        "--by",
        "image",
        "--yaw-bins",
        "30",
        "--worst",
        worst,
    )
    assert r.exit_code == 0, r.output
    return page, r.output


def test_page_content(tmp_path):
    from hpe_cli.metrics.protocols import PROTOCOLS

    page, out = _make_page(tmp_path)
    text = page.read_text()
    for p in PROTOCOLS.values():
        assert p.name in text and p.source.split(" ")[0] in text, p.name
    assert "By image" in text and "By GT yaw" in text and "[-30, 0)" in text
    assert "dad3dheads (unitless)" in text and "<sub>F</sub></td><td>unitless" in text
    assert "Worst 6 rows" in text and text.count("<img") >= 3  # the three plots
    worst = text.index("<h2>Worst 6 rows")
    assert text.index("image00514", worst) < text.index("image00475", worst)  # the 180-degree turn is first
    assert text.count('class="pic"') == 6  # one embedded picture per worst row
    # the terminal shows the same tables
    assert "by image" in out and "by GT yaw" in out and "source PinataFarms/DAD-3DHeads@" in out


def test_worst_pictures_are_the_drawn_faces(tmp_path):
    """Each worst row's picture is its own face (the source JPEG) with the two poses drawn over it."""
    import base64
    import re

    import cv2

    page, _ = _make_page(tmp_path, worst=4)
    text = page.read_text()
    body = text[text.index("<h2>Worst 4 rows") :]
    names = re.findall(r"<td>(image\d{5})(?:\.\w+)?</td>", body)  # the key as the GT reader gives it
    pics = re.findall(r'class="pic" src="data:image/jpeg;base64,([^"]+)"', body)
    assert len(names) == len(pics) == 4
    for name, b64 in zip(names, pics):
        drawn = cv2.imdecode(np.frombuffer(base64.b64decode(b64), np.uint8), cv2.IMREAD_COLOR)
        raw = cv2.imread(str(AFLW / f"{name}.jpg"))
        raw = cv2.resize(raw, (drawn.shape[1], drawn.shape[0]), interpolation=cv2.INTER_AREA)
        diff = np.abs(drawn.astype(int) - raw.astype(int)).max(axis=2)
        assert np.median(diff) < 12, name  # the same photo underneath
        assert (diff > 80).mean() > 0.002, name  # with lines drawn over it


def test_page_in_headless_chromium_with_pictures(tmp_path):
    browser = _browser()
    if browser is None:
        pytest.skip("no chromium installed (apt-get install -y chromium)")
    page, _ = _make_page(tmp_path)
    text = page.read_text()
    assert text.count('class="pic"') == 6  # every worst row has its picture
    shot = tmp_path / "shot.png"
    r = subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--hide-scrollbars",
            "--window-size=1400,5200",
            f"--screenshot={shot}",
            page.as_uri(),
        ],
        capture_output=True,
        timeout=120,
        check=False,
    )
    assert shot.is_file() and shot.stat().st_size > 50_000, r.stderr[-500:]
    import cv2

    img = cv2.imread(str(shot))
    assert img.shape[:2] == (5200, 1400)
    # the lower part (plots and worst-row pictures) is not blank: photos have many distinct colours
    lower = img[2400:]
    assert len(np.unique(lower.reshape(-1, 3) // 16, axis=0)) > 200
