#!/usr/bin/env python3
"""Every streaming command next to its floor, with peak memory, in one run.

For each size (default 1M and 10M rows) this builds the inputs in a temporary
folder, then runs, each as its own subprocess under ``/usr/bin/time`` (wall
time and peak RSS of that process alone):

* ``hpe convert`` on angles and on matrices (Parquet in, Parquet out), and on
  angles from CSV;
* ``hpe audit`` (JSON report);
* ``hpe augment --hflip`` (labels only);
* the COCO and WHENet writers against the Parquet writer on the same
  relabel-like table (in this process);
* ``hpe relabel-panoptic`` on 5,000 and 20,000 synthetic frames (views/s, one
  process and ``--workers 2``, next to an orjson parse of the tar), and its
  output formats (Parquet, COCO, WHENet) with landmarks on -- the runs of
  ``benchmarks/panoptic.py``.

Floors, measured in the same run the same way: a pyarrow script that reads
the same input and writes a table of the output's width with the encoding
hpe's writer uses (floats plain, the rest snappy + dictionary); for audit, a
read of the label columns alone.

Usage::

    nice python benchmarks/commands.py                      # 1M and 10M rows
    nice python benchmarks/commands.py --rows 200000        # quick look
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
HPE = [sys.executable, "-c", 'from hpe_cli.cli.main import cli; cli(prog_name="hpe")']

FLOOR = r"""
import sys, numpy as np, pyarrow as pa, pyarrow.parquet as pq, pyarrow.csv as pcsv
inp, out, width, kind = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
t = pcsv.read_csv(inp) if inp.endswith(".csv") else pq.read_table(inp)
if kind == "read":
    sys.exit(0)
n = t.num_rows
rng = np.random.default_rng(0)
k = 0
while t.num_columns < width - 1:
    t = t.append_column(f"x{k}", pa.array(rng.standard_normal(n))); k += 1
t = t.append_column("flag", pa.array(np.zeros(n, bool)))
floats = {f.name for f in t.schema if pa.types.is_floating(f.type)}
pq.write_table(t, out, use_dictionary=[c for c in t.schema.names if c not in floats],
               compression={c: ("none" if c in floats else "snappy") for c in t.schema.names})
"""


def timed(cmd, env) -> tuple:
    """Wall seconds, peak RSS (MB) and CPU seconds (user + system) of one subprocess, from GNU time."""
    fmt = "@@%e %M %U %S"
    res = subprocess.run(["/usr/bin/time", "-f", fmt] + cmd, env=env, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"failed ({res.returncode}): {' '.join(map(str, cmd))}\n{res.stderr[-2000:]}")
    line = [ln for ln in res.stderr.splitlines() if ln.startswith("@@")][-1]
    sec, kb, user, system = line[2:].split()
    # a process that reports its own peak (VmHWM) is believed over GNU time's, which can carry the launching
    # process's peak across exec
    own = [ln.split()[1] for ln in res.stdout.splitlines() if ln.startswith("@@hwm")]
    return float(sec), int(own[-1] if own else kb) / 1024, float(user) + float(system)


def best(cmd, env, repeat):
    runs = [timed(cmd, env) for _ in range(repeat)]
    return min(r[0] for r in runs), max(r[1] for r in runs), min(r[2] for r in runs)


WRITER = r"""
import sys, pyarrow.parquet as pq
from hpe_cli.io import TableWriter
from hpe_cli.io.coco import CocoWriter
from hpe_cli.io.whenet_txt import WhenetWriter
inp, out, fmt = sys.argv[1], sys.argv[2], sys.argv[3]
w = {"parquet": lambda: TableWriter(out, True), "coco": lambda: CocoWriter(out, True),
     "whenet": lambda: WhenetWriter(out, True)}[fmt]()
with w:
    for b in pq.ParquetFile(inp, pre_buffer=False, buffer_size=1 << 20).iter_batches(batch_size=65536,
                                                                                     use_threads=False):
        w.write(b)
print("@@hwm", [ln.split()[1] for ln in open("/proc/self/status") if ln.startswith("VmHWM")][0])
"""


def make_views(path: Path, n: int, n_lm: int = 70):
    """A relabel-panoptic-like output table: image, box, angles, image size, 70 2-D landmarks."""
    rng = np.random.default_rng(1)
    chunk = 200_000
    w = None
    for lo in range(0, n, chunk):
        m = min(chunk, n - lo)
        cols = {
            "image": pa.array(
                [f"171204_pose1/hdImgs/00_{k % 31:02d}/00_{k % 31:02d}_{k // 155:08d}.jpg" for k in range(lo, lo + m)]
            )
        }
        for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h", "pitch", "yaw", "roll"):
            cols[c] = rng.uniform(0, 500, m) if c.startswith("bbox") else rng.uniform(-90, 90, m)
        cols["image_width"] = np.full(m, 1920)
        cols["image_height"] = np.full(m, 1080)
        for i in range(n_lm):
            cols[f"lm{i}_x"] = rng.uniform(0, 1920, m)
            cols[f"lm{i}_y"] = rng.uniform(0, 1080, m)
        t = pa.table(cols)
        if w is None:
            w = pq.ParquetWriter(path, t.schema)
        w.write_table(t, row_group_size=65_536)
    w.close()


def make_inputs(tmp: Path, n: int):
    """angles.parquet, matrix.parquet, angles.csv (written in chunks: the parent stays small)."""
    sys.path.insert(0, str(ROOT))
    from hpe_cli.rotation import get_system

    system = get_system("300w_lp")
    rng = np.random.default_rng(0)
    chunk = 1_000_000
    wa = wm = wc = None
    for lo in range(0, n, chunk):
        m = min(chunk, n - lo)
        pyr = np.c_[rng.uniform(-89, 89, m), rng.uniform(-99, 99, m), rng.uniform(-89, 89, m)]
        ta = pa.table({"id": np.arange(lo, lo + m), "pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2]})
        R = system.from_angles(pyr).reshape(m, 9)
        tm = pa.table(
            {
                "id": np.arange(lo, lo + m),
                **{f"r{i}{j}": np.ascontiguousarray(R[:, 3 * i + j]) for i in range(3) for j in range(3)},
            }
        )
        if wa is None:
            wa = pq.ParquetWriter(tmp / "angles.parquet", ta.schema)
            wm = pq.ParquetWriter(tmp / "matrix.parquet", tm.schema)
            wc = pcsv.CSVWriter(tmp / "angles.csv", ta.schema)
        wa.write_table(ta)
        wm.write_table(tm)
        wc.write_table(ta)
    wa.close()
    wm.close()
    wc.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, nargs="*", default=[1_000_000, 10_000_000])
    ap.add_argument("--repeat", type=int, default=1, help="runs per measurement (best time, worst memory)")
    ap.add_argument(
        "--views",
        type=int,
        nargs="*",
        default=[775_000],
        help="rows of the writer benchmark (775,000 = 5,000 Panoptic frames x 5 people x 31 cameras)",
    )
    ap.add_argument(
        "--frames",
        type=int,
        nargs="*",
        default=[5_000, 20_000],
        help="Panoptic frames for relabel-panoptic (benchmarks/panoptic.py: 1 process and --workers 2, "
        "landmarks off); none skips it",
    )
    ap.add_argument(
        "--formats-frames",
        type=int,
        default=5_000,
        help="frames for relabel-panoptic's output formats (Parquet, COCO, WHENet; landmarks on); 0 skips",
    )
    args = ap.parse_args()
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    for n in args.views:
        with tempfile.TemporaryDirectory(dir=os.environ.get("HPE_BENCH_TMP")) as tmp:
            tmp = Path(tmp)
            make_views(tmp / "views.parquet", n)
            print(
                f"\nwriters, {n:,} relabel-like rows (image, box, angles, size, 70 landmarks), streamed in "
                "batches of 65,536; floor = hpe's Parquet writer on the same batches"
            )
            res = {
                fmt: best(
                    [sys.executable, "-c", WRITER, str(tmp / "views.parquet"), str(tmp / f"o.{fmt}"), fmt],
                    env,
                    args.repeat,
                )
                for fmt in ("parquet", "coco", "whenet")
            }
            tp, _, cp = res["parquet"]
            for fmt, (t, mb, c) in res.items():
                print(
                    f"  {fmt:<8} {t:7.2f} s ({t / tp:4.2f}x)  cpu {c:7.2f} s ({c / cp:4.2f}x)  peak {mb:5.0f} MB",
                    flush=True,
                )
    out_width = 1 + 3 + 3 + 9 + 2  # id, pitch..roll, pitch_2.., r00..r22, gimbal_lock, roundtrip_err
    for n in args.rows:
        with tempfile.TemporaryDirectory(dir=os.environ.get("HPE_BENCH_TMP")) as tmp:
            tmp = Path(tmp)
            make_inputs(tmp, n)
            o = tmp / "out.parquet"
            floor_cmd = lambda inp, width, kind="rw": [
                sys.executable,
                "-c",
                FLOOR,
                str(tmp / inp),
                str(o),  # noqa
                str(width),
                kind,
            ]
            jobs = [
                (
                    "convert angles (Parquet)",
                    HPE
                    + [
                        "convert",
                        tmp / "angles.parquet",
                        "-o",
                        o,
                        "--from",
                        "300w_lp",
                        "--to",
                        "scipy_zyx",
                        "-q",
                        "--overwrite",
                    ],
                    floor_cmd("angles.parquet", out_width),
                ),
                (
                    "convert matrices (Parquet)",
                    HPE
                    + [
                        "convert",
                        tmp / "matrix.parquet",
                        "-o",
                        o,
                        "--from",
                        "300w_lp",
                        "--to",
                        "scipy_zyx",
                        "-q",
                        "--overwrite",
                    ],
                    floor_cmd("matrix.parquet", out_width),
                ),
                (
                    "convert angles (CSV in)",
                    HPE
                    + [
                        "convert",
                        tmp / "angles.csv",
                        "-o",
                        o,
                        "--from",
                        "300w_lp",
                        "--to",
                        "scipy_zyx",
                        "-q",
                        "--overwrite",
                    ],
                    floor_cmd("angles.csv", out_width),
                ),
                (
                    "audit (JSON report)",
                    HPE + ["audit", tmp / "angles.parquet", "--json", tmp / "r.json", "-q", "--overwrite"],
                    floor_cmd("angles.parquet", 0, "read"),
                ),
                (
                    "augment --hflip (labels)",
                    HPE
                    + [
                        "augment",
                        tmp / "angles.parquet",
                        "-o",
                        o,
                        "--image-size",
                        "450",
                        "450",
                        "--hflip",
                        "-q",
                        "--overwrite",
                    ],
                    floor_cmd("angles.parquet", out_width),
                ),
            ]
            print(
                f"\n{n:,} rows (Parquet in, Parquet out unless noted); wall and CPU (user+sys) seconds, best of "
                f"{args.repeat}; RSS is each process's peak; the load average is printed because a shared "
                "machine inflates wall times"
            )
            print(
                f"  {'command':<28} {'hpe s':>7} {'floor s':>7} {'ratio':>6} {'hpe cpu':>7} {'floor cpu':>9} "
                f"{'cpu ratio':>9} {'hpe MB':>7} {'floor MB':>8}  load"
            )
            for name, cmd, fcmd in jobs:
                th, mh, ch = best([str(c) for c in cmd], env, args.repeat)
                tf, mf, cf = best(fcmd, env, args.repeat)
                print(
                    f"  {name:<28} {th:7.2f} {tf:7.2f} {th / tf:6.2f} {ch:7.2f} {cf:9.2f} {ch / cf:9.2f} "
                    f"{mh:7.0f} {mf:8.0f}  {os.getloadavg()[0]:.1f}",
                    flush=True,
                )

    if args.frames or args.formats_frames:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import panoptic

        with tempfile.TemporaryDirectory(dir=os.environ.get("HPE_BENCH_TMP")) as tmp:
            for n in args.frames:
                panoptic.bench_labels(n, Path(tmp), max(3, args.repeat), dask=False)
            if args.formats_frames:
                panoptic.bench_formats(args.formats_frames, Path(tmp), max(1, args.repeat))


if __name__ == "__main__":
    main()
