"""The docs site builds with warnings as errors, after the conventions atlas is regenerated from the code.

The atlas (``docs/atlas.md`` and ``docs/img/atlas/*.png``) is made by ``scripts/make_atlas.py``, which calls
``hpe``; this test regenerates it in a copy of ``docs/`` and builds that copy with ``mkdocs build --strict``, so
the pictures and formulas in the built site always come from the current code. The build imports no torch (the
torch API reference is read from the source): a ``torch`` that cannot be imported is put first on the path.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import repo_module

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="mkdocs is not installed")


def _atlas_module():
    return repo_module("scripts/make_atlas.py")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("site")
    docs = tmp / "docs"
    shutil.copytree(ROOT / "docs", docs)
    shutil.rmtree(docs / "img" / "atlas", ignore_errors=True)
    atlas = _atlas_module().build(docs)
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    (tmp / "mkdocs.yml").write_text(config, encoding="utf-8")
    no_torch = tmp / "no_torch" / "torch"
    no_torch.mkdir(parents=True)
    (no_torch / "__init__.py").write_text("raise ImportError('the docs build must not import torch')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp / "no_torch"), str(ROOT)]), NO_MKDOCS_2_WARNING="1")
    site = tmp / "site"
    p = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(tmp / "mkdocs.yml"), "-d", str(site)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    return p, site, docs, atlas


def test_mkdocs_build_strict(built):
    p, site, _, _ = built
    assert p.returncode == 0, p.stdout + p.stderr
    for page in (  # one .html per page: the offline plugin turns directory URLs off, so file:// links work
        "index.html",
        "atlas.html",
        "maths.html",
        "commands/convert.html",
        "api/python.html",
        "api/torch.html",
        "guarantees.html",
        "performance.html",
    ):
        assert (site / page).is_file(), page


def test_atlas_has_every_builtin_system(built):
    _, site, docs, atlas = built
    names = sorted(p.stem for p in (ROOT / "configs" / "systems").glob("*.toml"))
    text = atlas.read_text(encoding="utf-8")
    for name in names:
        assert f"## {name}\n" in text
        png = docs / "img" / "atlas" / f"{name}.png"
        assert png.is_file() and png.stat().st_size > 10_000, name
        assert (site / "img" / "atlas" / f"{name}.png").is_file()
    assert "SPEC" not in text


def test_committed_atlas_is_current(built):
    """docs/atlas.md in the repository is what the script writes now (rerun scripts/make_atlas.py if not)."""
    _, _, _, atlas = built
    assert (ROOT / "docs" / "atlas.md").read_text(encoding="utf-8") == atlas.read_text(encoding="utf-8"), (
        "docs/atlas.md is stale: run python scripts/make_atlas.py"
    )


def test_api_reference_rendered(built):
    _, site, _, _ = built
    python = (site / "api" / "python.html").read_text(encoding="utf-8")
    for name in ("get_system", "convert", "read_labels", "write_labels", "audit", "evaluate", "augment_batch"):
        assert name in python
    torch = (site / "api" / "torch.html").read_text(encoding="utf-8")
    for name in ("geodesic_loss", "HeadPose", "HeadPoseDataset", "from_matrix"):
        assert name in torch
    convert = (site / "commands" / "convert.html").read_text(encoding="utf-8")
    assert "--from" in convert and "--radians" in convert


def test_built_site_cites_no_internal_notes(built):
    _, site, _, _ = built
    for page in site.rglob("*.html"):
        assert "SPEC" not in page.read_text(encoding="utf-8"), page


def test_no_internal_design_notes_cited():
    """User-facing pages cite papers and peer code, not internal notes."""
    for page in (ROOT / "docs").rglob("*.md"):
        assert "SPEC" not in page.read_text(encoding="utf-8"), page
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "SPEC" not in readme


def test_the_site_loads_nothing_from_the_network(built):
    """Formulas render offline: MathJax is shipped with the site (docs/js/mathjax, unchanged from npm), no page
    asks a CDN for a script, a style sheet or a font."""
    import re

    p, site, _, _ = built
    assert p.returncode == 0, p.stdout + p.stderr
    assert (site / "js" / "mathjax" / "tex-chtml.js").stat().st_size > 500_000
    fonts = list((site / "js" / "mathjax" / "output" / "chtml" / "fonts" / "woff-v2").glob("*.woff"))
    assert len(fonts) >= 20  # MathJax's CHTML fonts, found next to the script
    remote = re.compile(r"<(?:script|link)\b[^>]*\b(?:src|href)=\"(https?:)?//[^\"]+\"")
    for page in ("maths.html", "atlas.html", "index.html"):
        html = (site / page).read_text(encoding="utf-8")
        assert "js/mathjax/tex-chtml.js" in html, page
        assert not remote.findall(html), (page, remote.findall(html))


# ------------------------------------------------------------------ in a browser (headless Chromium), from file://
def _chromium():
    return next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)


def _probe(site, page, script, width=1280, budget=15000):
    """Open ``page`` of the built site from file:// with ``script`` run in it; returns the ``data-probe`` attribute
    the script sets on <body>."""
    import re

    browser = _chromium()
    if browser is None:
        pytest.skip("no chromium installed")
    src = site / page
    probe = src.with_name("probe-" + src.name)
    probe.write_text(src.read_text(encoding="utf-8").replace("</body>", f"<script>{script}</script></body>"))
    r = subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            f"--window-size={width},900",
            f"--virtual-time-budget={budget}",
            "--dump-dom",
            probe.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )
    m = re.search(r'data-probe="([^"]*)"', r.stdout, re.S)
    assert m is not None, r.stderr[-800:]
    return m.group(1).replace("&quot;", '"')


@pytest.mark.parametrize("width", [1280, 1024])
def test_maths_formulas_fit_the_page(built, width):
    """No display formula (the elemental rotation matrices, the similarity fit) is wider than the text column."""
    _, site, _, _ = built
    script = (
        "window.addEventListener('load',()=>setTimeout(()=>{const bad=[];"
        "document.querySelectorAll('div.arithmatex').forEach(e=>{if(e.scrollWidth>e.clientWidth+1)"
        "bad.push(e.textContent.slice(0,40))});"
        "const n=document.querySelectorAll('mjx-container').length;"
        "document.body.setAttribute('data-probe',n+'|'+JSON.stringify(bad))},2000));"
    )
    n, bad = _probe(site, "maths.html", script, width).split("|", 1)
    assert int(n) > 10, "MathJax rendered no formula"
    assert bad == "[]", bad


def test_search_works_from_file_urls(built):
    """MkDocs Material's offline plugin (index shipped as a script, its Web Worker shim in docs/js/iframe-worker):
    typing in the search box of a page opened from disk lists results."""
    _, site, _, _ = built
    assert (site / "search" / "search_index.js").is_file()
    script = (
        "setTimeout(()=>{const i=document.querySelector('input[data-md-component=\"search-query\"]');"
        "i.focus();i.value='gimbal';i.dispatchEvent(new Event('input',{bubbles:true}));"
        "i.dispatchEvent(new KeyboardEvent('keyup',{bubbles:true,key:'l'}))},2000);"
        "setTimeout(()=>{const m=document.querySelector('.md-search-result__meta');"
        "document.body.setAttribute('data-probe',document.querySelectorAll('.md-search-result__item').length+'|'"
        "+(m?m.textContent.trim():''))},7000);"
    )
    items, meta = _probe(site, "index.html", script).split("|", 1)
    assert int(items) > 0 and "matching" in meta, (items, meta)
