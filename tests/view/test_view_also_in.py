"""``hpe view --also-in``: the page's angle filters in another named system.

Independent path: ``hpe convert --to SYSTEM`` of the same table (its own reader, converter and writer) says which
rows have yaw >= 30 in SYSTEM; the page, opened in headless Chromium with ``#sys=SYSTEM&yaw=30,``, must show
exactly those rows. The selector (driven over the DevTools protocol) switches the system and keeps it in the
address.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe

from .cdp import Browser
from .conftest import CHROMIUM_FLAGS, PIZZA, body_attrs, console_errors, open_page, page_data

pytestmark = pytest.mark.skipif(not PIZZA.is_dir(), reason="../shared/realdata is not available")
ALSO = ("3ddfa_v2", "300w_lp")


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    t = tmp_path_factory.mktemp("also")
    labels, page = t / "labels.parquet", t / "page"
    assert hpe("relabel-panoptic", PIZZA, "-o", labels, "--system", "whenet", "-q").exit_code == 0
    r = hpe("view", labels, "-o", page, "--images", PIZZA, "--rejects", t / "rej.csv", "--also-in", ",".join(ALSO),
            "-q")  # fmt: skip
    assert r.exit_code == 0, r.output
    return t, labels, page


def _converted(t, labels, system):
    out = t / f"{system}.parquet"
    if not out.exists():
        r = hpe("convert", labels, "-o", out, "--to", system, "-q")
        assert r.exit_code == 0, r.output
    return pd.read_parquet(out)


def _ids(dom):
    return sorted(int(x) for x in re.findall(r"-?\d+", re.search(r'<pre id="ids" hidden="">(.*?)</pre>', dom, re.S)[1]))


def test_page_angles_are_convert_s(page):
    t, labels, out = page
    data = page_data(out)
    assert data["meta"]["systems"] == ["whenet", *ALSO]
    for s in ALSO:
        conv = _converted(t, labels, s)
        for k in ("pitch", "yaw", "roll"):
            assert np.allclose(np.array(data["systems"][s][k], float), conv[k].to_numpy(), atol=6e-4, equal_nan=True)


def _R(axis, deg):
    return Rotation.from_euler(axis, np.asarray(deg)[:, None], degrees=True).as_matrix()


def test_the_two_systems_angles_are_one_rotation_in_scipy(page):
    """Oracle without hpe's kernels, from the systems' published formulas: 300W-LP's Pose_Para
    A = Rx(p).T Ry(y).T Rz(r).T and 3DDFA_V2's matrix2angle A = Rz(r) Ry(y).T Rx(p) (SciPy's elementary
    rotations): the page's angles in both systems must give the same matrix for every row."""
    _, _, out = page
    data = page_data(out)
    a = {s: [np.array(data["systems"][s][k], float) for k in ("pitch", "yaw", "roll")] for s in ALSO}
    ok = np.isfinite(np.stack(a["300w_lp"], 1)).all(1)
    assert ok.sum() > 1000
    p, y, r = (v[ok] for v in a["300w_lp"])
    A1 = np.swapaxes(_R("x", p), 1, 2) @ np.swapaxes(_R("y", y), 1, 2) @ np.swapaxes(_R("z", r), 1, 2)
    p, y, r = (v[ok] for v in a["3ddfa_v2"])
    A2 = _R("z", r) @ np.swapaxes(_R("y", y), 1, 2) @ _R("x", p)
    assert np.abs(A1 - A2).max() < 1e-4  # the page keeps 0.001 degree


@pytest.mark.parametrize("system", ALSO)
def test_filter_in_another_system_shows_the_rows_convert_says(page, chromium, tmp_path, system):
    t, labels, out = page
    conv = _converted(t, labels, system)
    yaw = conv["yaw"].to_numpy()
    want = (np.flatnonzero(yaw >= 30) + 1).tolist()  # Parquet rows are 1-based
    assert 0 < len(want) < len(conv)
    assert not np.any(np.abs(yaw - 30) < 1e-3)  # no row on the edge within the page's 0.001-degree rounding
    own = pd.read_parquet(labels)["yaw"].to_numpy()
    assert want != (np.flatnonzero(own >= 30) + 1).tolist() or system == "300w_lp"
    dom, err = open_page(chromium, out.joinpath("index.html").as_uri() + f"#sys={system}&yaw=30,&ids=1", tmp_path / "p")
    assert console_errors(err) == [], console_errors(err)
    assert _ids(dom) == want
    attrs = body_attrs(dom)
    assert attrs["data-system"] == system and attrs["data-shown"] == str(len(want))


def test_selector_switches_the_system_and_the_address(page, chromium, tmp_path):
    t, labels, out = page
    conv = _converted(t, labels, "3ddfa_v2")
    own = pd.read_parquet(labels)
    b = Browser(chromium, tmp_path / "prof", flags=CHROMIUM_FLAGS)
    try:
        b.goto(out.joinpath("index.html").as_uri() + "#yaw=30,")
        assert b.eval("document.body.dataset.shown") == str(int((own["yaw"] >= 30).sum()))
        b.eval(
            "const s = document.getElementById('system'); s.value = '3ddfa_v2'; s.dispatchEvent(new Event('change'))"
        )
        assert b.eval("document.body.dataset.shown") == str(int((conv["yaw"] >= 30).sum()))
        assert "sys=3ddfa_v2" in b.eval("location.hash")
        cap = b.eval("document.querySelector('.tile .cap').textContent")
        first = int(np.flatnonzero(conv["yaw"].to_numpy() >= 30)[0])
        assert cap.startswith(f"y {conv['yaw'].iloc[first]:.1f} p {conv['pitch'].iloc[first]:.1f}"), cap
        assert b.console() == []
    finally:
        b.close()
