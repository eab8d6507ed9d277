"""``hpe view`` pages opened in headless Chromium from ``file://``.

On the real CMU Panoptic 160906_pizza1 sample relabelled twice by ``hpe relabel-panoptic`` (corrected, and with
``--legacy-whenet``; WHENet's system, whose yaw spans +-180 degrees) and on the AFLW2000-3D samples: the page loads
with no console message, every thumbnail it shows decodes, a yaw >= 90 filter shows exactly the rows of the table
whose yaw is >= 90, and the detail view shows the frame, both poses, the landmarks and the row's file and row.
"""

from __future__ import annotations

import re

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe

from .conftest import AFLW, PIZZA, ROOT, body_attrs, console_errors, detail_chunk, open_page, page_data

pytestmark = pytest.mark.skipif(not PIZZA.is_dir(), reason="../shared/realdata is not available")


@pytest.fixture(scope="module")
def pizza(tmp_path_factory):
    """(corrected table, legacy table, page folder)."""
    t = tmp_path_factory.mktemp("pizza")
    corr, legacy, page = t / "corrected.parquet", t / "legacy.parquet", t / "page"
    for out, extra in ((corr, []), (legacy, ["--legacy-whenet"])):
        r = hpe("relabel-panoptic", PIZZA, "-o", out, "--system", "whenet", "-q", *extra)
        assert r.exit_code == 0, r.output
    r = hpe("view", corr, legacy, "-o", page, "--images", PIZZA, "--rejects", t / "rej.csv", "-q")
    assert r.exit_code == 0, r.output
    return corr, legacy, page


def _shown_images(dom):
    return re.findall(r'<img alt="" src="(thumbs/[0-9a-f]+\.jpg)"(?: style="")?>', dom)


def test_pizza_page_loads_clean_and_every_shown_image_decodes(pizza, chromium, tmp_path):
    corr, _, page = pizza
    data = page_data(page)
    ok = [t for t in data["thumb"] if t]
    assert 0 < len(ok) < 80  # the sample has the pictures of a few cameras only; all fit in the window
    dom, err = open_page(chromium, page.joinpath("index.html").as_uri() + "#c.status=ok", tmp_path / "prof")
    assert console_errors(err) == [], console_errors(err)
    attrs = body_attrs(dom)
    assert attrs["data-shown"] == str(len(ok))
    assert attrs.get("data-decoded") == str(len(ok)) and "data-broken" not in attrs, attrs
    assert '<pre id="errors" hidden="">' in dom  # no script error reached the page's own error box
    assert sorted(_shown_images(dom)) == sorted("thumbs/" + t for t in ok)
    for t in ok:  # the files themselves: JPEG thumbnails of the head crops
        img = cv2.imread(str(page / "thumbs" / t))
        assert img is not None and img.shape == (128, 128, 3), t
    for im in data["images"]:
        frame = cv2.imread(str(page / "frames" / im["f"]))
        assert frame is not None and max(frame.shape[:2]) == 960 and (im["w"], im["h"]) == (1920, 1080)


def test_yaw_filter_shows_exactly_the_rows_the_table_says(pizza, chromium, tmp_path):
    corr, _, page = pizza
    table = pd.read_parquet(corr)
    want = sorted((np.flatnonzero(table["yaw"].to_numpy() >= 90) + 1).tolist())  # Parquet rows are 1-based
    assert 0 < len(want) < len(table)
    assert want == sorted((np.flatnonzero(table["yaw"].to_numpy() > 90) + 1).tolist())  # no row sits on 90
    url = page.joinpath("index.html").as_uri() + "#yaw=90,&ids=1"
    dom, err = open_page(chromium, url, tmp_path / "prof")
    assert console_errors(err) == []
    ids = re.search(r'<pre id="ids" hidden="">(.*?)</pre>', dom, re.S).group(1)
    assert sorted(int(x) for x in re.findall(r"-?\d+", ids)) == want
    assert body_attrs(dom)["data-shown"] == str(len(want))
    assert f"showing {len(want):,} of {len(table):,} rows" in dom
    # and a range on both sides, in the other direction: -180 <= yaw < -90
    dom, _ = open_page(chromium, page.joinpath("index.html").as_uri() + "#yaw=-180,-90&ids=1", tmp_path / "prof")
    ids = re.search(r'<pre id="ids" hidden="">(.*?)</pre>', dom, re.S).group(1)
    y = table["yaw"].to_numpy()
    assert sorted(int(x) for x in re.findall(r"-?\d+", ids)) == (np.flatnonzero((y >= -180) & (y < -90)) + 1).tolist()


def test_detail_view_shows_frame_poses_landmarks_and_source(pizza, chromium, tmp_path):
    corr, legacy, page = pizza
    data = page_data(page)
    i = next(k for k, t in enumerate(data["thumb"]) if t)  # the first row with a picture
    row = data["num"]["row"][i]
    dom, err = open_page(chromium, page.joinpath("index.html").as_uri() + f"#open={row}", tmp_path / "prof")
    assert console_errors(err) == []
    assert body_attrs(dom)["data-open"] == str(row)
    assert f"{corr}: row {row}" in dom
    legacy_rows = pd.read_parquet(legacy)
    t = pd.read_parquet(corr).iloc[i]
    j = np.flatnonzero((legacy_rows["image"] == t["image"]) & (legacy_rows["person_id"] == t["person_id"]))
    assert len(j) == 1 and f"other: {legacy}: row {j[0] + 1}" in dom
    assert re.search(r'<img src="frames/[0-9a-f]+\.jpg" alt="full frame" id="detail-img">', dom)
    svg = dom[dom.index("<svg", dom.index('class="frame"')) : dom.index("</svg>", dom.index('class="frame"'))]
    lines = re.findall(r"<line [^>]*>", svg)
    assert len(lines) == 6 and sum("stroke-dasharray" in x for x in lines) == 3  # labels solid, OTHER dashed
    assert svg.count("<circle") == 70 and svg.count("<rect") == 1  # the 70 Panoptic landmarks and the head box
    # every column of the row is listed
    for col in ("camera", "person_id", "bbox_w", "fit_rmse", "lm69_y"):
        assert f"<td>{col}</td>" in dom, col


def test_detail_geometry_matches_the_table_and_the_face(pizza):
    """The overlay's numbers are the table's (box, landmarks), and the pose lines it draws agree with the face
    (physical consistency): the red line (subject's left) runs along the eyes from the subject's right eye to the
    left one, the green line (forehead to chin) from the eyes towards the mouth (68-point scheme: 36-41 right eye,
    42-47 left eye, 48-67 mouth)."""
    corr, _, page = pizza
    table = pd.read_parquet(corr)
    cos_red, cos_green = [], []
    for k in range(-(-len(table) // 1000)):
        d = detail_chunk(page, k)
        for j in range(len(d["box"])):
            t = table.iloc[k * 1000 + j]
            assert np.allclose(d["box"][j], t[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy(float))
            lm = np.array([[t[f"lm{q}_x"], t[f"lm{q}_y"]] for q in range(70)])
            assert np.allclose(np.array(d["lm"][j], float).reshape(70, 2), lm, atol=0.006)
            v = np.array(d["vec"][j], float).reshape(3, 2)
            eyes = lm[42:48].mean(0) - lm[36:42].mean(0)
            down = lm[48:68].mean(0) - (lm[36:48].mean(0))
            if np.linalg.norm(eyes) > 10 and np.linalg.norm(v[0]) > 0.5:
                cos_red.append(v[0] @ eyes / np.linalg.norm(v[0]) / np.linalg.norm(eyes))
            if np.linalg.norm(down) > 10 and np.linalg.norm(v[1]) > 0.5:
                cos_green.append(v[1] @ down / np.linalg.norm(v[1]) / np.linalg.norm(down))
    assert len(cos_red) > 500 and np.median(cos_red) > 0.95, np.median(cos_red)
    assert len(cos_green) > 500 and np.median(cos_green) > 0.9, np.median(cos_green)


def test_aflw_pages_open_clean(chromium, tmp_path):
    for src in (ROOT / "sample_data" / "aflw2000", AFLW):
        if not src.is_dir():
            continue
        page = tmp_path / src.name
        r = hpe("view", src, "-o", page, "-q")
        assert r.exit_code == 0, r.output
        n = len(list(src.glob("*.mat")))
        data = page_data(page)
        assert data["meta"]["n"] == n and data["meta"]["counts"]["whole_frame"] == n  # .mat rows have no box
        dom, err = open_page(chromium, page.joinpath("index.html").as_uri(), tmp_path / "prof")
        assert console_errors(err) == []
        attrs = body_attrs(dom)
        assert attrs["data-shown"] == str(n) and attrs.get("data-decoded") == str(n) and "data-broken" not in attrs


def test_sort_and_category_filter_from_the_address(pizza, chromium, tmp_path):
    """``#c.camera=00_08&sort=-yaw``: only camera 00_08's rows, largest yaw first (ties in file order)."""
    corr, _, page = pizza
    table = pd.read_parquet(corr)
    url = page.joinpath("index.html").as_uri() + "#c.camera=00_08&sort=-yaw&ids=1"
    dom, err = open_page(chromium, url, tmp_path / "prof")
    assert console_errors(err) == []
    ids = [int(x) for x in re.findall(r"-?\d+", re.search(r'<pre id="ids" hidden="">(.*?)</pre>', dom, re.S).group(1))]
    sub = table[table["camera"] == "00_08"]
    yaw = np.round(sub["yaw"].to_numpy(), 3)  # the page keeps 0.001 degree
    want = (sub.index.to_numpy()[np.lexsort((sub.index.to_numpy(), -yaw))] + 1).tolist()
    assert ids == want and len(ids) > 10
