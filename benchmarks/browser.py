"""Headless Chromium as the benchmarks and the tests open hpe's offline pages (``hpe view``, the evaluate report).

One list of flags for both (a benchmark never imports the tests): no sandbox or GPU (containers), and nothing
that reaches the network on its own (background networking, component updates, sync, first-run pages), so a
page that loads anything from the network fails visibly instead of being helped by the browser.
"""

from __future__ import annotations

import shutil

#: flags every headless run uses; callers add their window size or scrollbar choice
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)


def find_chromium():
    """The path of ``chromium``, ``chromium-browser`` or ``google-chrome`` (first found on ``PATH``), or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None
