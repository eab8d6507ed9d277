"""``hpe evaluate --report page.html`` on the AFLW2000 sample with shuffled predictions, opened in headless Chromium.

The page must show every protocol with its source, the ``--by`` and
``--yaw-bins`` tables, the row counts, units per column (DAD-3DHeads'
Frobenius unitless), the plots and the worst rows; with ``hpe draw``'s
``draw_worst`` available the worst rows carry their pictures (here a stand-in
``draw_worst`` draws them, so this test does not depend on the draw work).
"""
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hpe_cli.cli.main import cli

SHARED = Path(__file__).resolve().parents[3] / "shared"
AFLW = SHARED / "realdata" / "aflw2000_prnet"
PRED = SHARED / "golden" / "evaluate" / "aflw16m" / "pred.csv"
pytestmark = pytest.mark.skipif(not (AFLW.is_dir() and PRED.is_file()), reason="shared data not available")


def _browser():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def _stub_draw_worst(rows, *, images, out_dir, worst, sort_by):
    """Stand-in for hpe_cli.pipelines.draw.draw_worst: the source image with two labels, one file per row."""
    import cv2

    paths = []
    frame = rows.sort_values(sort_by, ascending=False).head(worst)
    for i, r in enumerate(frame.itertuples()):
        img = cv2.imread(r.image_path)
        cv2.putText(img, f"GT yaw {r.gt_yaw:.0f}", (5, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 200, 0), 2)
        cv2.putText(img, f"pred yaw {r.pred_yaw:.0f}", (5, 45), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 230), 2)
        p = Path(out_dir) / f"{i:03d}.jpg"
        cv2.imwrite(str(p), img)
        paths.append(str(p))
    return paths


def _make_page(tmp_path, monkeypatch=None, worst=6):
    pred = tmp_path / "shuffled.csv"
    pd.read_csv(PRED).sample(frac=1.0, random_state=11).to_csv(pred, index=False)
    if monkeypatch is not None:
        from hpe_cli.pipelines import draw

        monkeypatch.setattr(draw, "draw_worst", _stub_draw_worst, raising=False)
    page = tmp_path / "page.html"
    r = CliRunner().invoke(cli, ["evaluate", str(pred), str(AFLW), "--pred-system", "300w_lp", "--gt-system",
                                 "300w_lp", "--report", str(page), "--by", "image", "--yaw-bins", "30",
                                 "--worst", str(worst)], catch_exceptions=False)
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
    assert "aflw2000_prnet/image00514.jpg" in text  # the worst row (a 180-degree turn) names its image
    # the terminal shows the same tables
    assert "by image" in out and "by GT yaw" in out and "source PinataFarms/DAD-3DHeads@" in out


def test_page_in_headless_chromium_with_pictures(tmp_path, monkeypatch):
    browser = _browser()
    if browser is None:
        pytest.skip("no chromium installed (apt-get install -y chromium)")
    page, _ = _make_page(tmp_path, monkeypatch)
    text = page.read_text()
    assert text.count('class="pic"') == 6  # every worst row has its picture
    shot = tmp_path / "shot.png"
    r = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                        "--hide-scrollbars", "--window-size=1400,5200", f"--screenshot={shot}", page.as_uri()],
                       capture_output=True, timeout=120, check=False)
    assert shot.is_file() and shot.stat().st_size > 50_000, r.stderr[-500:]
    import cv2

    img = cv2.imread(str(shot))
    assert img.shape[:2] == (5200, 1400)
    # the lower part (plots and worst-row pictures) is not blank: photos have many distinct colours
    lower = img[2400:]
    assert len(np.unique(lower.reshape(-1, 3) // 16, axis=0)) > 200
