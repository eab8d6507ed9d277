"""``hpe view`` on a large synthetic table: build time, rebuild time (thumbnails cached) and page-open time.

Run:  python benchmarks/view.py [--rows 100000] [--images 5] [--threads 2] [--repeat 3]

The table has ``--rows`` faces cut from a handful of 1280x720 JPEGs (random boxes, random poses, camera /
person / split columns and a flag column). Printed, each beside its floor measured in the same run:

- build: ``python -m hpe_cli view`` as a process (wall, peak RSS); floor: a bare OpenCV loop over the same rows
  (crop, resize to 128 px the same way, JPEG encode, write; images decoded once; no table, no drawing, no
  transaction, one thread);
- rebuild into the same folder with ``--overwrite`` (every thumbnail reused);
- page open in headless Chromium from ``file://``: the page's own ``performance.now()`` when the first grid is
  drawn (navigation start -> data parsed, filters built, first tiles placed) and the browser process's wall
  time; floor: the same browser opening an empty page.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from benchmarks.browser import CHROMIUM_FLAGS, find_chromium  # noqa: E402  (one flag list with tests/view)

FLAGS = [*CHROMIUM_FLAGS, "--window-size=1400,900"]


def make_data(folder: Path, rows: int, images: int, seed: int = 0):
    import cv2
    import pandas as pd

    rng = np.random.default_rng(seed)
    (folder / "imgs").mkdir(parents=True)
    for k in range(images):
        img = cv2.GaussianBlur(rng.uniform(0, 255, (720, 1280, 3)), (0, 0), 4)
        img = ((img - img.min()) / (img.max() - img.min()) * 255).astype(np.uint8)
        cv2.imwrite(str(folder / "imgs" / f"cam{k}.jpg"), img)
    w = rng.uniform(60, 240, rows)
    table = pd.DataFrame(
        {
            "image": [f"cam{k}.jpg" for k in rng.integers(0, images, rows)],
            "camera": [f"{k:02d}" for k in rng.integers(0, 31, rows)],
            "person_id": rng.integers(0, 8, rows),
            "split": np.where(rng.random(rows) < 0.8, "train", "test"),
            "pitch": rng.uniform(-60, 60, rows),
            "yaw": rng.uniform(-90, 90, rows),
            "roll": rng.uniform(-40, 40, rows),
            "bbox_x": rng.uniform(0, 1280 - 240, rows),
            "bbox_y": rng.uniform(0, 720 - 240, rows),
            "bbox_w": w,
            "bbox_h": w * rng.uniform(0.9, 1.2, rows),
            "gimbal_lock": rng.random(rows) < 0.01,
        }
    )
    path = folder / "labels.parquet"
    table.to_parquet(path, index=False)
    return path, table


def run_hpe(args) -> tuple:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "hpe_cli", *map(str, args)], capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t
    if r.returncode:
        raise SystemExit(r.stdout + r.stderr)
    return dt, r.stdout + r.stderr


def floor_thumbnails(folder: Path, table, out: Path) -> float:
    """Crop, resize, encode and write every row's thumbnail (images decoded once): the least any tool does."""
    import cv2

    out.mkdir()
    imgs = {p.name: cv2.imread(str(p)) for p in (folder / "imgs").iterdir()}
    b = table[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy()
    names = table["image"].tolist()
    t = time.perf_counter()
    for i in range(len(table)):
        x, y, w, h = b[i]
        s = max(w, h) * 1.6
        x0, y0 = max(0, int(x + w / 2 - s / 2)), max(0, int(y + h / 2 - s / 2))
        crop = imgs[names[i]][y0 : y0 + int(s), x0 : x0 + int(s)]
        k = crop.shape[0] // 128  # area-average by an integer factor (OpenCV's fast path), then bilinear
        if k >= 2:
            m = crop.shape[0] // k
            crop = cv2.resize(crop[: m * k, : m * k], (m, m), interpolation=cv2.INTER_AREA)
        small = cv2.resize(crop, (128, 128), interpolation=cv2.INTER_LINEAR)
        ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, 82])
        (out / f"{i}.jpg").write_bytes(buf.tobytes())
    return time.perf_counter() - t


def open_page(browser: str, url: str, profile: Path) -> tuple:
    """(page's first-render time in ms or None, browser wall time in s)."""
    t = time.perf_counter()
    r = subprocess.run(
        [browser, *FLAGS, f"--user-data-dir={profile}", "--dump-dom", url], capture_output=True, text=True, timeout=300
    )
    wall = time.perf_counter() - t
    m = re.search(r'data-ready-ms="(\d+)"', r.stdout)
    shown = re.search(r'data-shown="(\d+)"', r.stdout)
    return (int(m.group(1)) if m else None), wall, (int(shown.group(1)) if shown else None)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--images", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    browser = find_chromium()
    with tempfile.TemporaryDirectory(prefix="hpe-view-bench-") as tmp:
        tmp = Path(tmp)
        labels, table = make_data(tmp, args.rows, args.images)
        page = tmp / "page"
        build, out = run_hpe(
            ["view", labels, "-o", page, "--images", tmp / "imgs", "--threads", args.threads, "--title", "bench"]
        )
        rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        rebuild, out2 = run_hpe(
            ["view", labels, "-o", page, "--images", tmp / "imgs", "--threads", args.threads, "--overwrite", "-q"]
        )
        floor = floor_thumbnails(tmp, table, tmp / "floor")
        size = (page / "rows.js").stat().st_size / 1e6
        print(f"hpe view, {args.rows:,} rows from {args.images} images, {args.threads} threads")
        print("  " + next((x for x in out.splitlines() if "rows shown" in x), out.strip()[-300:]))
        print(f"  build        {build:7.1f} s   floor (bare OpenCV loop, 1 thread) {floor:6.1f} s   "
              f"ratio {build / floor:4.2f}   hpe peak RSS {rss:.0f} MB")  # fmt: skip
        print(f"  rebuild (every thumbnail reused) {rebuild:7.1f} s")
        print(f"  rows.js {size:.1f} MB; thumbnails {sum(1 for _ in (page / 'thumbs').iterdir()):,}")
        if browser is None:
            print("  no chromium: page-open time not measured")
            return
        empty = tmp / "empty.html"
        empty.write_text("<!doctype html><title>empty</title><body data-ready-ms=0></body>")
        ready, walls, floors, shown = [], [], [], None
        for k in range(args.repeat):
            ms, wall, shown = open_page(browser, page.joinpath("index.html").as_uri(), tmp / f"prof{k}")
            ready.append(ms)
            walls.append(wall)
            floors.append(open_page(browser, empty.as_uri(), tmp / f"prof-empty{k}")[1])
        print(
            f"  page open (median of {args.repeat}): first grid drawn at {statistics.median(ready):.0f} ms after "
            f"navigation start ({shown:,} rows shown); browser process {statistics.median(walls):.2f} s, "
            f"empty page {statistics.median(floors):.2f} s (floor)"
        )


if __name__ == "__main__":
    main()
