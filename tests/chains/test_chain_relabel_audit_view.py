"""relabel-panoptic (real pizza1, WHENet's system) -> audit -o (one flag column per check) -> view: the page offers
each audit flag as a filter, and in headless Chromium ``#f.out_of_range=1`` shows exactly the rows audit flagged.
Also relabel -> augment (crop) -> view: the augmented table and its pictures open as a page."""

import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest
from view.conftest import page_data

from conftest import hpe

from .conftest import PIZZA

pytestmark = pytest.mark.skipif(not PIZZA.is_dir(), reason="../shared/realdata is not available")


def test_relabel_audit_view_flags(tmp_path):
    labels, flags, page = tmp_path / "labels.parquet", tmp_path / "flags.parquet", tmp_path / "page"
    assert hpe("relabel-panoptic", PIZZA, "-o", labels, "--system", "whenet", "-q").exit_code == 0
    assert hpe("audit", labels, "-o", flags, "-q").exit_code == 0
    r = hpe("view", flags, "-o", page, "--images", PIZZA, "--rejects", tmp_path / "rej.csv", "-q")
    assert r.exit_code == 0, r.output
    audited = pd.read_parquet(flags)
    d = page_data(page)
    assert {"gimbal_lock", "out_of_range", "flagged"} <= set(d["flag"])
    assert d["flag"]["out_of_range"] == audited["out_of_range"].astype(int).tolist()
    want = (np.flatnonzero(audited["out_of_range"].to_numpy()) + 1).tolist()
    assert want  # WHENet's legacy rule: some views are out of its range
    browser = next(
        (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None
    )
    if browser is None:
        pytest.skip("no chromium installed")
    url = page.joinpath("index.html").as_uri() + "#f.out_of_range=1&ids=1"
    out = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={tmp_path / 'prof'}",
         "--virtual-time-budget=5000", "--dump-dom", url],
        capture_output=True, text=True, timeout=180, check=False,
    ).stdout  # fmt: skip
    ids = re.search(r'<pre id="ids" hidden="">(.*?)</pre>', out, re.S).group(1)
    assert sorted(int(x) for x in re.findall(r"\d+", ids)) == want


def test_relabel_augment_view(tmp_path):
    labels, aug, page = tmp_path / "labels.parquet", tmp_path / "aug.parquet", tmp_path / "page"
    r = hpe("relabel-panoptic", PIZZA, "-o", labels, "--cameras", "00_00,00_08", "--frames", "1147:1148", "-q")
    assert r.exit_code == 0, r.output
    r = hpe(
        "augment", labels, "-o", aug, "--images", PIZZA, "--out-images", tmp_path / "imgs", "--hflip", "-q",
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    r = hpe("view", aug, "-o", page, "--images", tmp_path / "imgs", "-q")
    assert r.exit_code == 0, r.output
    d = page_data(page)
    n = len(pd.read_parquet(aug))
    assert d["meta"]["n"] == n and sum(t is not None for t in d["thumb"]) == n
