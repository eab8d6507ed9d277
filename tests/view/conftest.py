"""Helpers of the ``hpe view`` tests: build pages with the CLI, read their data files, open them in headless
Chromium (the same browser lookup as the evaluate report tests; skipped when no Chromium is installed)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from benchmarks.browser import CHROMIUM_FLAGS as _BASE_FLAGS
from benchmarks.browser import find_chromium

ROOT = Path(__file__).resolve().parents[2]
#: ../shared next to the checkout (or next to the folder of worktrees that holds it)
SHARED = next((p / "shared" for p in ROOT.parents if (p / "shared" / "realdata").is_dir()), ROOT.parent / "shared")
REALDATA = SHARED / "realdata"
PIZZA = REALDATA / "panoptic_160906_pizza1"
AFLW = REALDATA / "aflw2000_prnet"
PRED = SHARED / "golden" / "evaluate" / "aflw16m" / "pred.csv"
#: the benchmarks' headless flags (benchmarks/browser.py: one list for both), scrollbars hidden for screenshots
CHROMIUM_FLAGS = [*_BASE_FLAGS, "--hide-scrollbars"]


def browser():
    return find_chromium()


@pytest.fixture
def chromium():
    path = browser()
    if path is None:
        pytest.skip("no chromium installed (apt-get install -y chromium)")
    return path


def page_data(page: Path) -> dict:
    """``window.HPE_VIEW`` of a page folder, as Python."""
    text = (page / "rows.js").read_text(encoding="utf-8")
    assert text.startswith("window.HPE_VIEW=") and text.rstrip().endswith(";")
    return json.loads(text[len("window.HPE_VIEW=") : text.rstrip().rindex(";")])


def detail_chunk(page: Path, k: int) -> dict:
    text = (page / "rows" / f"{k:05d}.js").read_text(encoding="utf-8")
    head = f"HPE_VIEW_ROWS({k},"
    assert text.startswith(head)
    return json.loads(text[len(head) : text.rstrip().rindex(")")])


def open_page(browser_path, url: str, profile: Path, size=(1400, 2000), budget_ms=8000, screenshot=None):
    """Load ``url`` in headless Chromium; ``(DOM after the page settled, stderr)``.

    ``--virtual-time-budget`` lets the page's scripts and image loads finish before the DOM is dumped;
    ``--enable-logging=stderr`` puts the page's console messages (``CONSOLE``/``Uncaught``) on stderr.
    """
    args = [
        browser_path,
        *CHROMIUM_FLAGS,
        f"--user-data-dir={profile}",
        "--enable-logging=stderr",
        "--v=0",
        f"--window-size={size[0]},{size[1]}",
        f"--virtual-time-budget={budget_ms}",
    ]
    args += [f"--screenshot={screenshot}"] if screenshot else ["--dump-dom"]
    r = subprocess.run([*args, url], capture_output=True, text=True, timeout=180, check=False)
    return r.stdout, r.stderr


def console_errors(stderr: str) -> list:
    """Console messages and script errors of the page in Chromium's log."""
    return [
        line
        for line in stderr.splitlines()
        if ("CONSOLE" in line or "Uncaught" in line or ":ERROR:" in line and "file://" in line)
    ]


def body_attrs(dom: str) -> dict:
    import re

    m = re.search(r"<body([^>]*)>", dom)
    assert m, dom[:500]
    return dict(re.findall(r'([\w-]+)="([^"]*)"', m.group(1)))
