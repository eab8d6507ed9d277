"""Clicks in the page (headless Chromium driven over the DevTools protocol): a coverage-map cell filters the grid
to the rows of that yaw-pitch cell and puts the filter in the address; a click on a face opens it in full."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import hpe

from .cdp import Browser
from .conftest import CHROMIUM_FLAGS, PIZZA, page_data

pytestmark = pytest.mark.skipif(not PIZZA.is_dir(), reason="../shared/realdata is not available")


@pytest.fixture
def page(tmp_path):
    labels = tmp_path / "labels.parquet"
    assert hpe("relabel-panoptic", PIZZA, "-o", labels, "--system", "whenet", "-q").exit_code == 0
    out = tmp_path / "page"
    r = hpe("view", labels, "-o", out, "--images", PIZZA, "--rejects", tmp_path / "rej.csv", "-q")
    assert r.exit_code == 0, r.output
    return labels, out


def test_coverage_cell_click_filters_and_face_click_opens(page, chromium, tmp_path):
    labels, out = page
    table = pd.read_parquet(labels)
    y, p = table["yaw"].to_numpy(), table["pitch"].to_numpy()
    # the most populated 10-degree cell
    cells = pd.Series(list(zip(np.floor(y / 10).astype(int), np.floor(p / 10).astype(int)))).value_counts()
    (cy, cp), n = cells.index[0], int(cells.iloc[0])
    b = Browser(chromium, tmp_path / "prof", flags=CHROMIUM_FLAGS)
    try:
        b.goto(out.joinpath("index.html").as_uri())
        assert b.eval("document.body.dataset.shown") == str(len(table))
        rect = b.eval(
            "(() => { const r = coverage.getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; })()"
        )
        # cell (cy, cp): yaw -180 + 10 k across, pitch -180 + 10 j upwards, 36 x 36 cells
        kx, ky = cy + 18, cp + 18
        x = rect[0] + (kx + 0.5) * rect[2] / 36
        yy = rect[1] + (36 - 1 - ky + 0.5) * rect[3] / 36
        b.click(x, yy)
        assert b.eval("document.body.dataset.shown") == str(n)
        h = b.eval("location.hash")
        assert f"yaw={cy * 10},{cy * 10 + 10}" in h and f"pitch={cp * 10},{cp * 10 + 10}" in h, h
        # a click on the same cell clears it
        b.click(x, yy)
        assert b.eval("document.body.dataset.shown") == str(len(table))
        # click the first face with a picture: the detail view opens with its row
        b.eval("document.querySelector('select[data-cat=status]').value = 'ok';"
               "document.querySelector('select[data-cat=status]').dispatchEvent(new Event('change'))")  # fmt: skip
        data = page_data(out)
        first = next(k for k, t in enumerate(data["thumb"]) if t)
        tile = b.eval(
            "(() => { const r = document.querySelector('.tile').getBoundingClientRect(); return [r.left + 60, r.top + 60]; })()"
        )
        b.click(*tile)
        b.wait_for("!document.getElementById('detail').hidden")  # its rows/00000.js comes in first
        assert b.eval("document.body.dataset.open") == str(data["num"]["row"][first])
        assert b.eval("document.getElementById('detail-src').textContent") == f"{labels}: row {first + 1}"
        assert b.eval("location.hash").endswith(f"open={first + 1}")
        assert b.console() == []
    finally:
        b.close()
