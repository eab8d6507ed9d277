#!/usr/bin/env python3
"""Benchmark ``hpe export`` (crops/s) against a bare OpenCV loop on the same images, in the same run.

Makes ``--images`` synthetic 1920x1080 JPEG frames (smooth gradients plus noise, quality 90) with
``--heads`` head boxes each (about 180 px, one partly outside the frame), and a label table. Then times:

1. the floor: for each image ``cv2.imdecode`` once, then per head slice + ``cv2.resize`` to SIZE x SIZE +
   ``cv2.imencode`` + write the file (no padding, no labels, no bookkeeping);
1b. the same floor decoding the way ``hpe export`` does when ``_hpe_jpeg`` is built (only the union of the
   frame's head boxes, OpenCV's pixels): the floor for the command's own cost;
2. ``hpe export --layout whenet --square --size SIZE`` with ``--workers 1`` and ``--workers 2``, each in a fresh
   process: the wall time with Python start-up and imports, and the command alone (reading the table, labels,
   rejects, crops, annotation.txt, staging and commit) once its modules are imported.

Each line prints crops/s, the ratio to the floor (the mean of a floor run before and after) and the peak RSS.
Then the scaling: ``--workers 1/2`` and ``--scheduler local --workers 1/2`` (a Dask LocalCluster), crops/s per
worker and what the LocalCluster adds. ``--videos FRAMES`` runs the scaling on a synthetic multi-sequence
release made from videos instead (units of one video x 256 frames).

Usage::

    python benchmarks/export.py                     # 200 frames x 3 heads, size 224
    python benchmarks/export.py --images 1000 --heads 4 --size 112
    python benchmarks/export.py --videos 300 --cameras 2     # 2 sequences x 2 videos x 300 frames
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # an in-place build of _hpe_jpeg (setup.py build_ext --inplace) sits in the root


def make_data(folder: Path, n_images: int, heads: int, seed: int = 0):
    import cv2
    import pandas as pd

    rng = np.random.default_rng(seed)
    (folder / "img").mkdir(parents=True)
    yy, xx = np.mgrid[0:1080, 0:1920]
    base = np.stack([(xx / 8) % 256, (yy / 5) % 256, ((xx + yy) / 11) % 256], -1).astype(np.uint8)
    rows = []
    for i in range(n_images):
        img = cv2.add(base, rng.integers(0, 40, base.shape, dtype=np.uint8))
        cv2.imwrite(str(folder / "img" / f"{i:06d}.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 90])
        for h in range(heads):
            x = 1800 if h == heads - 1 else 100 + 400 * h
            rows.append(
                {
                    "image": f"img/{i:06d}.jpg",
                    "sequence": "bench",
                    "camera": f"00_{h:02d}",
                    "frame": i,
                    "person_id": h,
                    "bbox_x": float(x),
                    "bbox_y": 300.0 + 10 * h,
                    "bbox_w": 180.0,
                    "bbox_h": 180.0,
                    "pitch": float(rng.uniform(-60, 60)),
                    "yaw": float(rng.uniform(-80, 80)),
                    "roll": float(rng.uniform(-40, 40)),
                }
            )
    pd.DataFrame(rows).to_parquet(folder / "labels.parquet")
    return folder / "labels.parquet", rows


def floor_loop(folder: Path, rows, size: int, out: Path, region: bool = False) -> float:
    import cv2

    cv2.setNumThreads(1)
    out.mkdir()
    by_image = {}
    for r in rows:
        by_image.setdefault(r["image"], []).append(r)
    t0 = time.perf_counter()
    k = 0
    for image, heads in by_image.items():
        with open(folder / image, "rb") as fh:
            data = fh.read()
        top = left = 0
        if region:  # the union of the heads' boxes only, as hpe export decodes it
            import _hpe_jpeg

            xs, ys = [int(r["bbox_x"]) for r in heads], [int(r["bbox_y"]) for r in heads]
            band, rows_, stride, H, W, top, left, dy, dx = _hpe_jpeg.decode_region(
                data, min(ys), min(xs), max(ys) + 180, max(xs) + 180, False
            )
            img = np.frombuffer(band, np.uint8).reshape(rows_, stride // 3, 3)[dy:, dx:]
        else:
            img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        for r in heads:
            x0, y0 = int(r["bbox_x"]), int(r["bbox_y"])
            crop = img[max(y0, 0) - top : y0 + 180 - top, max(x0, 0) - left : x0 + 180 - left]
            crop = cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA)
            ok, buf = cv2.imencode(".jpg", crop, [cv2.IMWRITE_JPEG_QUALITY, 95])
            buf.tofile(str(out / f"{k}.jpg"))
            k += 1
    return time.perf_counter() - t0


def run_hpe(labels: Path, images: Path, out: Path, size: int, workers: int, extra=(), prefix=()):
    """One ``hpe export`` in a fresh process: (seconds with start-up and imports, seconds of the command alone
    after its modules are imported, peak RSS in KB)."""
    code = (
        "import time; t00 = time.perf_counter(); import resource, sys\n"
        "from hpe_cli.cli.main import cli; import hpe_cli.pipelines.export, hpe_cli.cli.export, pandas, pyarrow, "
        "pyarrow.parquet, cv2, scipy.io\n"
        "t0 = time.perf_counter()\n"
        "try:\n    cli(sys.argv[1:])\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
        "t1 = time.perf_counter()\n"
        "hwm = [int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
        "rss = max(hwm, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
        "print(t1 - t00, t1 - t0, rss)"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t_start = time.perf_counter()
    r = subprocess.run(
        [
            *prefix,
            sys.executable,
            "-c",
            code,
            "export",
            str(labels),
            "-o",
            str(out),
            "--layout",
            "whenet",
            "--images",
            str(images),
            "--square",
            "--size",
            str(size),
            "--workers",
            str(workers),
            *extra,
            "-q",
        ],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    wall = time.perf_counter() - t_start
    _, dt, rss = r.stdout.split()
    return wall, float(dt), int(rss)


def make_videos(folder: Path, frames: int, cameras: int, sequences: int = 2):
    """A synthetic multi-sequence release made from 1920x1080 mp4v videos (``make_sample_data``) and its labels
    (``hpe relabel-panoptic``, one process): ``(labels, n_heads)``."""
    import importlib.util

    import pyarrow.parquet as pq

    spec = importlib.util.spec_from_file_location("make_sample_data", ROOT / "scripts" / "make_sample_data.py")
    mk = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mk)
    names = [f"seq{k}" for k in range(sequences)]
    mk.make_video_release(folder / "rel", names, cameras=cameras, frames=frames, people=2, short=0)
    labels = folder / "labels.parquet"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    subprocess.run(
        [sys.executable, "-m", "hpe_cli", "relabel-panoptic", str(folder / "rel"), "-o", str(labels), "-q"],
        env=env,
        check=True,
    )
    return labels, pq.read_metadata(labels).num_rows


def _unit_imports(_):
    t = time.perf_counter()
    import cv2  # noqa: F401

    import hpe_cli.datasets.panoptic_video  # noqa: F401
    import hpe_cli.pipelines.export.units  # noqa: F401
    import hpe_cli.pipelines.export.workers  # noqa: F401

    return time.perf_counter() - t


def cluster_overhead(workers: int = 2) -> None:
    """The fixed cost of ``--scheduler local``: starting the LocalCluster, its workers' first imports, closing."""
    try:
        from hpe_cli.pipelines.dask_runner import dask_client
    except ImportError:
        return
    t0 = time.perf_counter()
    try:
        with dask_client("local", workers) as c:
            t1 = time.perf_counter()
            imports = c.gather([c.submit(_unit_imports, i, pure=False) for i in range(workers)])
            t2 = time.perf_counter()
    except Exception as exc:  # no distributed
        print(f"LocalCluster: not measured ({exc})")
        return
    t3 = time.perf_counter()
    print(
        f"LocalCluster of {workers}: start {t1 - t0:.2f} s, first unit's imports {t2 - t1:.2f} s "
        f"(in the workers: {', '.join(f'{v:.2f}' for v in imports)} s), close {t3 - t2:.2f} s"
    )


def scaling(labels: Path, images: Path, tmp: Path, size: int, n: int) -> None:
    """``--workers 1/2`` and ``--scheduler local --workers 1/2``: crops/s, crops/s per worker, and what a
    LocalCluster adds over local processes (its start, the scheduler's round trips, the parts folder)."""
    res = {}
    for label, w, extra in (
        ("--workers 1", 1, ()),
        ("--workers 2", 2, ()),
        ("--scheduler local --workers 1", 1, ("--scheduler", "local")),
        ("--scheduler local --workers 2", 2, ("--scheduler", "local")),
    ):
        if extra:
            try:
                import distributed  # noqa: F401
            except ImportError:
                print(f"hpe export {label}: skipped (dask distributed is not installed)")
                continue
        wall, dt, rss = run_hpe(labels, images, tmp / f"s{len(res)}", size, w, extra)
        res[label] = dt
        print(
            f"hpe export {label:31s} {n / dt:8.1f} crops/s, {n / dt / w:8.1f} per worker (command {dt:.2f} s, "
            f"with start-up {wall:.2f} s); peak RSS of the parent {rss / 1024:.0f} MB"
        )
    if "--workers 2" in res:
        print(f"2 workers / 1 worker: {res['--workers 1'] / res['--workers 2']:.2f}x")
    if "--workers 2" in res and shutil.which("taskset") and (os.cpu_count() or 1) >= 2:
        # one worker is not one core: OpenCV's FFmpeg decoder runs threads of its own (a 1-worker run uses about
        # 1.35 cores here), so the per-worker scaling is measured against one worker held to one core
        wall, dt, rss = run_hpe(labels, images, tmp / "pinned", size, 1, (), ("taskset", "-c", "0"))
        print(
            f"hpe export --workers 1 on one core (taskset) {n / dt:8.1f} crops/s (command {dt:.2f} s); "
            f"2 workers on 2 cores / 1 worker on 1 core: {dt / res['--workers 2']:.2f}x"
        )
    cluster_overhead(2)
    for w in (1, 2):
        a, b = res.get(f"--workers {w}"), res.get(f"--scheduler local --workers {w}")
        if a and b:
            print(f"LocalCluster of {w} over --workers {w}: +{b - a:.2f} s ({b / a:.2f}x)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=200)
    ap.add_argument("--heads", type=int, default=3)
    ap.add_argument("--size", type=int, default=224)
    ap.add_argument(
        "--videos",
        type=int,
        default=0,
        metavar="FRAMES",
        help="instead: a release of 2 sequences x --cameras videos of FRAMES 1920x1080 frames (2 people), "
        "exported with --workers 1/2 and --scheduler local --workers 1/2",
    )
    ap.add_argument("--cameras", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.videos:
            labels, n = make_videos(tmp / "v", args.videos, args.cameras)
            print(f"2 sequences x {args.cameras} videos x {args.videos} frames 1920x1080 (mp4v), {n} heads")
            scaling(labels, tmp / "v" / "rel", tmp, args.size, n)
            return
        labels, rows = make_data(tmp / "data", args.images, args.heads)
        n = len(rows)
        print(f"{args.images} frames 1920x1080, {n} heads, crops {args.size}x{args.size}, JPEG q95")
        # the floor runs before and after the hpe runs (the machine may be shared): their mean is the floor
        t1 = floor_loop(tmp / "data", rows, args.size, tmp / "floor1")
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        runs = [(w, *run_hpe(labels, tmp / "data", tmp / f"out{w}", args.size, w)) for w in (1, 2)]
        t2 = floor_loop(tmp / "data", rows, args.size, tmp / "floor2")
        t_floor = (t1 + t2) / 2
        print(
            f"floor   bare imdecode+resize+imencode loop: {n / t_floor:8.1f} crops/s  ({t1:.2f} s and {t2:.2f} s, "
            f"peak RSS {rss0 / 1024:.0f} MB)"
        )
        try:
            import _hpe_jpeg  # noqa: F401
        except ImportError:
            pass
        else:
            t3 = floor_loop(tmp / "data", rows, args.size, tmp / "floor3", region=True)
            print(
                f"floor   the same, union-of-heads decode:  {n / t3:8.1f} crops/s  ({t3:.2f} s, "
                f"{t3 / t_floor:.2f}x the floor)"
            )
        scaling(labels, tmp / "data", tmp, args.size, n)
        for w, wall, dt, rss in runs:
            print(
                f"hpe export --workers {w}:  {n / wall:8.1f} crops/s with start-up ({wall:.2f} s, "
                f"{wall / t_floor:.2f}x the floor); command alone {n / dt:8.1f} crops/s ({dt:.2f} s, "
                f"{dt / t_floor:.2f}x); peak RSS {rss / 1024:.0f} MB"
            )


if __name__ == "__main__":
    main()
