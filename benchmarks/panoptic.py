#!/usr/bin/env python3
"""Benchmark ``hpe relabel-panoptic`` at scale and the Panoptic video path.

For each size (default 20,000 and 5,000 frames x 5 people x 31 HD cameras, built by
``scripts/make_sample_data.py --plain --tar``, faces read from ``hdFace3d.tar`` in place), in
fresh processes:

- floor: reading and parsing every face JSON of the tar with orjson (no maths, no output);
- ``hpe`` in one process (streaming, landmarks off), with ``--workers 2`` (each worker writes its own
  parts), and on a 2-worker Dask ``LocalCluster`` (``--scheduler local``);

each as views/s (face x camera) and peak RSS (the process and its largest worker). Then the video
path: frames/s of :class:`hpe_cli.datasets.panoptic_video.VideoFrames` reading every frame and every
10th frame of one synthetic video, next to a bare ``cv2.VideoCapture.read()`` loop over the same video.

Usage::

    python benchmarks/panoptic.py                       # 20000 and 5000 frames
    python benchmarks/panoptic.py --frames 2000 --video-frames 300
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RUNNER = r"""
import json, resource, sys, time
from pathlib import Path
sys.path.insert(0, {root!r})
mode, seq, out = sys.argv[1], sys.argv[2], sys.argv[3]
import numpy as np, pyarrow, pyarrow.parquet
from hpe_cli.pipelines import panoptic as job
from hpe_cli.datasets import panoptic as pan
t0 = time.perf_counter()
if mode == "floor":
    import orjson
    refs = pan.face_sources(seq)
    n = 0
    for r in refs.values():
        n += len(orjson.loads(r.read_bytes())["people"])
    views = n * 31
else:
    p = job.plan(seq)
    cfg = job.Config(landmarks=False)
    kw = dict(workers=1)
    if mode == "workers2":
        kw = dict(workers=2)
    elif mode == "dask2":
        kw = dict(workers=2, scheduler="local")
    st = job.write_outputs(p, cfg, Path(out), overwrite=True, **kw)
    views = st.views
dt = time.perf_counter() - t0
me = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
print(json.dumps({{"views": views, "seconds": dt, "rss_mb": me, "worker_rss_mb": kids}}))
"""


def _gen():
    spec = importlib.util.spec_from_file_location("make_sample_data", ROOT / "scripts" / "make_sample_data.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run_mode(mode: str, seq: Path, out: Path) -> dict:
    code = RUNNER.format(root=str(ROOT))
    r = subprocess.run([sys.executable, "-c", code, mode, str(seq), str(out)], capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(f"{mode} failed:\n{r.stderr}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def bench_labels(n_frames: int, tmp: Path) -> None:
    gen = _gen()
    seq = tmp / f"seq{n_frames}"
    t = time.perf_counter()
    gen.make_synthetic(seq, n_frames, 5, 31, special=False)
    gen.pack_tar(seq)
    print(f"\n{n_frames} frames x 5 people x 31 cameras (hdFace3d.tar, {(seq / 'hdFace3d.tar').stat().st_size / 1e6:.0f} MB,"
          f" built in {time.perf_counter() - t:.0f} s)")
    print(f"  {'run':34s} {'views/s':>10s} {'seconds':>8s} {'x 1 proc':>8s} {'peak RSS MB':>12s} {'worker MB':>10s}")
    base = None
    for mode, label in (("floor", "floor: orjson parse of the tar"), ("single", "hpe, 1 process"),
                        ("workers2", "hpe --workers 2"), ("dask2", "hpe --scheduler local (2 workers)")):
        res = run_mode(mode, seq, tmp / f"out_{mode}.parquet")
        rate = res["views"] / res["seconds"]
        if mode == "single":
            base = rate
        ratio = f"{rate / base:.2f}" if base and mode != "floor" else ""
        print(f"  {label:34s} {rate:10,.0f} {res['seconds']:8.1f} {ratio:>8s} {res['rss_mb']:12.0f} "
              f"{res['worker_rss_mb']:10.0f}")
    outs = [tmp / f"out_{m}.parquet" for m in ("single", "workers2", "dask2")]
    same = len({o.read_bytes() for o in outs}) == 1
    print(f"  outputs byte-identical across 1 process, 2 workers and the LocalCluster: {same}")


def bench_video(n_frames: int, size, tmp: Path) -> None:
    import cv2

    from hpe_cli.datasets.panoptic_video import VideoFrames

    gen = _gen()
    seq = tmp / "vid"
    gen.make_synthetic(seq, 2, 1, 1, special=False, first_frame=0)
    path = gen.write_videos(seq, n_frames - 1, size)[0]
    print(f"\nvideo: {n_frames} frames {size[0]}x{size[1]} mp4v ({path.stat().st_size / 1e6:.1f} MB)")
    t = time.perf_counter()
    cap = cv2.VideoCapture(str(path))
    n = 0
    while True:
        ok, _ = cap.read()
        if not ok:
            break
        n += 1
    cap.release()
    bare = n / (time.perf_counter() - t)
    print(f"  {'bare cv2.VideoCapture.read() loop':40s} {bare:8.0f} frames/s")
    for step in (1, 10):
        want = range(0, n_frames, step)
        t = time.perf_counter()
        got = sum(img is not None for _, img, _ in VideoFrames(path).read(want))
        dt = time.perf_counter() - t
        print(f"  {'VideoFrames.read(every ' + str(step) + ')':40s} {n_frames / dt:8.0f} video frames/s "
              f"({got / dt:.0f} returned/s, {n_frames / dt / bare:.2f}x the bare loop)")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, nargs="+", default=[20000, 5000])
    ap.add_argument("--video-frames", type=int, default=600)
    ap.add_argument("--video-size", default="1920x1080")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.frames:
            bench_labels(n, Path(tmp))
        w, h = (int(v) for v in a.video_size.split("x"))
        bench_video(a.video_frames, (w, h), Path(tmp))


if __name__ == "__main__":
    main()
