#!/usr/bin/env python3
"""Benchmark reading the named text formats (hpe_cli.io.columns) against pyarrow's own CSV reader.

Writes a WHENet ``annotation.txt`` of N lines (default 2,000,000) with a blank
line every 100,000 lines, then in one process times:

1. the floor: ``pyarrow.csv.read_csv`` of the same file (no line numbers, all threads);
2. ``open_table(path, with_lines=True)`` streamed batch by batch (``__line__`` per row,
   blank lines dropped, string image column), as every command reads it;
3. the same with a column map (``--columns-map``), which only renames.

Peak RSS (ru_maxrss) is printed after each step; the streamed read keeps
memory flat in N (the floor holds the whole table).

Usage::

    python benchmarks/text_formats.py            # 2,000,000 lines
    python benchmarks/text_formats.py --lines 200000
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines", type=int, default=2_000_000)
    args = ap.parse_args()
    import pyarrow.csv as pcsv

    from hpe_cli.io import open_table

    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "annotation.txt"
        ang = rng.uniform(-90, 90, size=(args.lines, 3))
        with open(p, "w") as fh:
            for start in range(0, args.lines, 100_000):
                chunk = ang[start : start + 100_000]
                fh.write(
                    "".join(
                        f"seq/{start + i:08d}.jpg,{y!r},{q!r},{r!r}\n" for i, (y, q, r) in enumerate(chunk.tolist())
                    )
                )
                fh.write("\n")
        size = p.stat().st_size / 1e6
        print(f"{args.lines} lines, {size:.0f} MB; start RSS {rss_mb():.0f} MB")
        t = time.perf_counter()
        tab = pcsv.read_csv(p, read_options=pcsv.ReadOptions(column_names=["image", "yaw", "pitch", "roll"]))
        floor = time.perf_counter() - t
        n_floor = tab.num_rows
        del tab
        print(
            f"floor  pyarrow.csv.read_csv        {floor:7.2f} s  {n_floor / floor / 1e6:6.2f} M rows/s  "
            f"peak RSS {rss_mb():.0f} MB"
        )
        for label, kw in (
            ("hpe    open_table(with_lines)", {}),
            ("hpe    + --columns-map", {"columns": "Y=yaw,P=pitch,R=roll"}),
        ):
            t = time.perf_counter()
            n = 0
            last = 0
            for b in open_table(p, with_lines=True, **kw).batches():
                n += b.num_rows
                last = b.column(b.schema.get_field_index("__line__"))[-1].as_py()
            dt = time.perf_counter() - t
            print(
                f"{label:30s} {dt:7.2f} s  {n / dt / 1e6:6.2f} M rows/s  peak RSS {rss_mb():.0f} MB "
                f"({n} rows, last line {last})"
            )


if __name__ == "__main__":
    main()
