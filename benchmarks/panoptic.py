#!/usr/bin/env python3
"""Benchmark ``hpe relabel-panoptic`` at scale and the Panoptic video path.

For each size (default 20,000 and 5,000 frames x 5 people x 31 HD cameras, built by
``scripts/make_sample_data.py --plain --tar``, faces read from ``hdFace3d.tar`` in place), in
fresh processes:

- floor: reading and parsing every face JSON of the tar with orjson (no maths, no output);
- ``hpe`` in one process (streaming, landmarks off), with ``--workers 2`` (each worker writes its own
  parts), and on a 2-worker Dask ``LocalCluster`` (``--scheduler local``);

each as views/s (face x camera) and peak RSS (the process and its largest worker), every mode run
``--repeat`` times in turn (single, workers2, ... single, workers2, ...) and the medians printed, the
ratio to one process taken pair by pair (a shared or virtual machine drifts; pairing cancels the drift).
Then the output formats with landmarks on (``--format table`` to Parquet, ``coco``, ``whenet``; one
process and ``--workers 2``): seconds, user and system CPU, and each format's time over Parquet's in the
same round (``--formats-frames``; 0 skips it). Then the video
path: frames/s of :class:`hpe_cli.datasets.panoptic_video.VideoFrames` reading every frame and every
10th frame of one synthetic video, next to a bare ``cv2.VideoCapture.read()`` loop over the same video.

Usage::

    python benchmarks/panoptic.py                       # 20000 and 5000 frames
    python benchmarks/panoptic.py --frames 5000 --repeat 7 --formats-frames 5000
    python benchmarks/panoptic.py --frames 2000 --video-frames 300 --repeat 1
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
mode, seq, out, fmt, lm = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5] == "1"
import numpy as np, pyarrow, pyarrow.parquet
from hpe_cli.pipelines.relabel import panoptic as job, plan as planning
from hpe_cli.pipelines.relabel.options import RelabelPanopticOptions
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
    kw = dict(workers=1)
    if mode == "workers2":
        kw = dict(workers=2)
    elif mode == "dask2":
        kw = dict(workers=2, scheduler="local")
    with job.worker_pool(**kw) as pool:  # as the CLI does: the workers start while the sequence is planned
        p = planning.plan(seq)
        opts = RelabelPanopticOptions(landmarks=lm, fmt=fmt, overwrite=True, **kw)
        st = job.write_outputs(p, Path(out), opts, pool=pool)
    views = st.views
dt = time.perf_counter() - t0
me, ch = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
# this process's own peak (VmHWM: ru_maxrss would carry the launching process's peak across exec)
hwm = [int(ln.split()[1]) for ln in open("/proc/self/status") if ln.startswith("VmHWM")]
peak = hwm[0] / 1024 if hwm else me.ru_maxrss / 1024
print(json.dumps({{"views": views, "seconds": dt, "rss_mb": peak, "worker_rss_mb": ch.ru_maxrss / 1024,
                  "user": me.ru_utime + ch.ru_utime, "sys": me.ru_stime + ch.ru_stime}}))
"""


def sample_data_script():
    """``scripts/make_sample_data.py`` as a module (also used by the other benchmarks)."""
    spec = importlib.util.spec_from_file_location("make_sample_data", ROOT / "scripts" / "make_sample_data.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run_mode(mode: str, seq: Path, out: Path, fmt: str = "table", landmarks: bool = False) -> dict:
    code = RUNNER.format(root=str(ROOT))
    r = subprocess.run(
        [sys.executable, "-c", code, mode, str(seq), str(out), fmt, str(int(landmarks))], capture_output=True, text=True
    )
    if r.returncode:
        raise SystemExit(f"{mode} failed:\n{r.stderr}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _digest(path: Path) -> str:
    """sha256 of a file, read in blocks (this process stays small: its children are measured)."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 22), b""):
            h.update(block)
    return h.hexdigest()


def _median(xs):
    import statistics

    return statistics.median(xs)


def _sequence(n_frames: int, tmp: Path) -> Path:
    seq = tmp / f"seq{n_frames}"
    if not (seq / "hdFace3d.tar").exists():
        gen = sample_data_script()
        t = time.perf_counter()
        gen.make_synthetic(seq, n_frames, 5, 31, special=False)
        gen.pack_tar(seq)
        print(
            f"\n{n_frames} frames x 5 people x 31 cameras (hdFace3d.tar, "
            f"{(seq / 'hdFace3d.tar').stat().st_size / 1e6:.0f} MB, built in {time.perf_counter() - t:.0f} s)"
        )
    return seq


def bench_labels(n_frames: int, tmp: Path, repeat: int, dask: bool) -> None:
    seq = _sequence(n_frames, tmp)
    modes = [("floor", "floor: orjson parse of the tar"), ("single", "hpe, 1 process"), ("workers2", "hpe --workers 2")]
    if dask:
        modes.append(("dask2", "hpe --scheduler local (2 workers)"))
    runs = {m: [] for m, _ in modes}
    for _ in range(repeat):
        for mode, _ in modes:
            runs[mode].append(run_mode(mode, seq, tmp / f"out_{mode}.parquet"))
    print(
        f"\n{n_frames} frames, landmarks off, Parquet out; medians of {repeat} rounds (ratio: per round, "
        "over the 1-process run of that round)"
    )
    print(f"  {'run':34s} {'views/s':>10s} {'seconds':>8s} {'x 1 proc':>8s} {'peak RSS MB':>12s} {'worker MB':>10s}")
    for mode, label in modes:
        rs = runs[mode]
        rate = _median([r["views"] / r["seconds"] for r in rs])
        ratio = ""
        if mode not in ("floor", "single"):
            ratio = f"{_median([a['seconds'] / b['seconds'] for a, b in zip(runs['single'], rs)]):.2f}"
            ratio += (
                f" ({min(a['seconds'] / b['seconds'] for a, b in zip(runs['single'], rs)):.2f}-"
                f"{max(a['seconds'] / b['seconds'] for a, b in zip(runs['single'], rs)):.2f})"
            )
        print(
            f"  {label:34s} {rate:10,.0f} {_median([r['seconds'] for r in rs]):8.2f} {ratio:>8s} "
            f"{max(r['rss_mb'] for r in rs):12.0f} {max(r['worker_rss_mb'] for r in rs):10.0f}"
        )
    outs = [tmp / f"out_{m}.parquet" for m, _ in modes if m != "floor"]
    same = len({_digest(o) for o in outs}) == 1
    print(f"  outputs byte-identical across the runs: {same}")


def bench_formats(n_frames: int, tmp: Path, repeat: int) -> None:
    seq = _sequence(n_frames, tmp)
    combos = [(fmt, mode) for mode in ("single", "workers2") for fmt in ("table", "coco", "whenet")]
    suffix = {"table": ".parquet", "coco": ".json", "whenet": ".txt"}
    runs = {c: [] for c in combos}
    for _ in range(repeat):
        for fmt, mode in combos:
            runs[(fmt, mode)].append(run_mode(mode, seq, tmp / f"fmt_{mode}{suffix[fmt]}", fmt, landmarks=True))
    print(
        f"\n{n_frames} frames, landmarks on, each output format; medians of {repeat} rounds (x Parquet: per "
        "round, over the Parquet run with the same workers)"
    )
    print(
        f"  {'format':8s} {'run':10s} {'seconds':>8s} {'x Parquet':>16s} {'user s':>7s} {'sys s':>6s} "
        f"{'peak MB':>8s} {'output MB':>10s}"
    )
    for fmt, mode in combos:
        rs, base = runs[(fmt, mode)], runs[("table", mode)]
        q = [a["seconds"] / b["seconds"] for a, b in zip(rs, base)]
        size = (tmp / f"fmt_{mode}{suffix[fmt]}").stat().st_size / 1e6
        print(
            f"  {fmt:8s} {mode:10s} {_median([r['seconds'] for r in rs]):8.2f} "
            f"{_median(q):6.2f} ({min(q):.2f}-{max(q):.2f}) {_median([r['user'] for r in rs]):7.2f} "
            f"{_median([r['sys'] for r in rs]):6.2f} {max(max(r['rss_mb'], r['worker_rss_mb']) for r in rs):8.0f} "
            f"{size:10.0f}"
        )
    for fmt in ("coco", "whenet"):
        a, b = (tmp / f"fmt_{m}{suffix[fmt]}" for m in ("single", "workers2"))
        print(f"  {fmt}: 1 process and --workers 2 byte-identical: {_digest(a) == _digest(b)}")


def bench_video(n_frames: int, size, tmp: Path) -> None:
    import cv2

    from hpe_cli.datasets.panoptic_video import VideoFrames

    gen = sample_data_script()
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
        print(
            f"  {'VideoFrames.read(every ' + str(step) + ')':40s} {n_frames / dt:8.0f} video frames/s "
            f"({got / dt:.0f} returned/s, {n_frames / dt / bare:.2f}x the bare loop)"
        )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, nargs="*", default=[20000, 5000])
    ap.add_argument("--repeat", type=int, default=5, help="rounds of every mode (medians are printed)")
    ap.add_argument("--dask", action="store_true", help="also run on a 2-worker Dask LocalCluster")
    ap.add_argument(
        "--formats-frames",
        type=int,
        default=5000,
        help="frames of the output-format comparison (landmarks on); 0 skips it",
    )
    ap.add_argument("--formats-repeat", type=int, default=3)
    ap.add_argument(
        "--workdir", help="keep the generated sequences here (reused by later runs) instead of a temporary folder"
    )
    ap.add_argument("--video-frames", type=int, default=600)
    ap.add_argument("--video-size", default="1920x1080")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import contextlib

    where = contextlib.nullcontext(a.workdir) if a.workdir else tempfile.TemporaryDirectory()
    with where as tmp:
        Path(tmp).mkdir(parents=True, exist_ok=True)
        for n in a.frames:
            bench_labels(n, Path(tmp), a.repeat, a.dask)
        if a.formats_frames:
            bench_formats(a.formats_frames, Path(tmp), a.formats_repeat)
        w, h = (int(v) for v in a.video_size.split("x"))
        bench_video(a.video_frames, (w, h), Path(tmp))


if __name__ == "__main__":
    main()
