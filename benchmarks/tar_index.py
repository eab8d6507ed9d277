#!/usr/bin/env python3
"""Indexing ``hdFace3d.tar``: the stdlib ``tarfile`` path next to hpe's header scanner.

For each size (default 5,000 and 20,000 frames; one person per frame, about 7 KB of face JSON per
member, built by ``scripts/make_sample_data.py``'s ``make_synthetic`` + ``pack_tar``, as
``--plain --tar`` does), prints the median of 5 runs of

- floor: ``hpe_cli.datasets.panoptic._tar_frames_tarfile`` (headers read by ``tarfile``, the path
  every archive took before, and still takes when it is not plain);
- ``hpe``: ``tar_frames`` (``_scan_plain_tar``: one ``pread`` per header, numpy checks);

with microseconds per member, the speed-up, the peak memory each path allocates (tracemalloc, in
a separate untimed run) and the process's peak RSS. Both results are checked to be equal.

Usage::

    python benchmarks/tar_index.py                     # 5000 and 20000 members
    python benchmarks/tar_index.py --members 2000 --keep /tmp/tars
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from panoptic import sample_data_script  # noqa: E402  (benchmarks/panoptic.py, beside this file)

from hpe_cli.datasets import panoptic as pan  # noqa: E402


def build(root: Path, n: int) -> Path:
    """``root/seq<n>/hdFace3d.tar`` with n face members (reused if it is there)."""
    seq = root / f"seq{n}"
    tar = seq / "hdFace3d.tar"
    if not tar.exists():
        gen = sample_data_script()
        gen.make_synthetic(seq, n_frames=n, n_people=1, n_cameras=3, special=False)
        gen.pack_tar(seq)
    return tar


def median_time(fn, tar, repeat=5) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn(tar)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def peak_alloc(fn, tar) -> float:
    tracemalloc.start()
    fn(tar)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2**20


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--members", type=int, nargs="+", default=[5000, 20000])
    ap.add_argument("--keep", type=Path, help="build the archives here and keep them (default: a temp folder)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = a.keep or Path(tmp)
        for n in a.members:
            tar = build(root, n)
            slow, fast = pan._tar_frames_tarfile(tar), pan.tar_frames(tar)
            assert pan._tar_frames_fast(tar) is not None, "the fast path gave up on a plain archive"
            assert slow == fast and list(slow) == list(fast), "the two paths differ"
            size = tar.stat().st_size / 2**20
            print(f"{n:,} members ({size:.0f} MB), median of 5 runs")
            t_slow = median_time(pan._tar_frames_tarfile, tar)
            t_fast = median_time(pan.tar_frames, tar)
            for label, t, fn in (
                ("floor: tarfile (_tar_frames_tarfile)", t_slow, pan._tar_frames_tarfile),
                ("hpe tar_frames (header scanner)", t_fast, pan.tar_frames),
            ):
                print(
                    f"  {label:<40} {t * 1e3:8.1f} ms  {t / n * 1e6:6.1f} us/member  "
                    f"peak alloc {peak_alloc(fn, tar):5.1f} MB"
                )
            print(f"  speed-up {t_slow / t_fast:.1f}x")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
