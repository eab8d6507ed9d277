"""Throughput of the rotation kernels (next to SciPy) and of `hpe convert` next to its streaming I/O floor.

    python benchmarks/convert.py [--rows 1000000] [--repeat 3] [--threads N] [--data DIR] [--skip-kernels]

Kernels (in this process): matrix -> both solutions >= 5M rows/s (issue 2). End to end (each run its own
process under GNU time, see benchmarks/streaming.py): `hpe convert` on angles and on matrices against
pyarrow reading the same input and writing a table of the output's width batch by batch; medians of the
rounds, wall and CPU ratios and peak RSS. Targets (issue 33): <= 1.15x the floor, <= 400 MB at 10M rows.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from streaming import HPE, ROOT, compare, floor_cmd, make_angles

from hpe_cli.io import LABEL_COLS
from hpe_cli.rotation import get_system


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def line(name, rows, seconds, ref=None):
    extra = f"   {seconds / ref:5.2f}x the baseline time" if ref else ""
    print(f"  {name:<46} {rows / seconds / 1e6:8.2f} M rows/s  ({seconds * 1e3:8.1f} ms){extra}")


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3, help="alternating rounds of hpe and floor (medians)")
    ap.add_argument("--threads", type=int, default=None, help="hpe convert --threads (default: its own)")
    ap.add_argument("--data", default=None, help="folder keeping the generated inputs between runs")
    ap.add_argument("--skip-kernels", action="store_true", help="only the end-to-end comparison")
    args = ap.parse_args()
    n = args.rows
    main_end_to_end(args, n)


def kernels(n):
    rng = np.random.default_rng(0)
    pyr = np.c_[rng.uniform(-180, 180, n), rng.uniform(-90, 90, n), rng.uniform(-180, 180, n)]
    src, dst = get_system("300w_lp"), get_system("scipy_zyx")
    R = dst.from_canonical(src.from_angles(pyr))

    print(f"kernels, {n:,} rows")
    t_sp = best_of(lambda: Rotation.from_matrix(R).as_euler("ZYX"))
    line("SciPy from_matrix().as_euler('ZYX') (1 solution)", n, t_sp)
    t = best_of(lambda: dst.to_angles(R))
    line("hpe matrix (N,3,3) -> both solutions + lock", n, t, t_sp)
    cols = [[np.ascontiguousarray(R[:, i, j]) for j in range(3)] for i in range(3)]
    t = best_of(lambda: dst.soa_to_angles(cols))
    line("hpe matrix columns -> both solutions + lock", n, t, t_sp)
    t_sp2 = best_of(lambda: Rotation.from_euler("ZYX", pyr, degrees=True).as_matrix())
    line("SciPy from_euler('ZYX').as_matrix()", n, t_sp2)
    line("hpe angles -> matrix (N,3,3)", n, best_of(lambda: dst.from_angles(pyr)), t_sp2)
    p, y, r = (np.ascontiguousarray(pyr[:, k]) for k in range(3))
    line("hpe angle columns -> matrix columns", n, best_of(lambda: dst.soa_from_angles(p, y, r)), t_sp2)


def hpe_source() -> str:
    """The ``hpe_cli`` the timed commands import: ``-c`` puts the current folder first on ``sys.path``, so run from
    a checkout's root it is that checkout's, whatever ``PYTHONPATH`` says."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-c", "import hpe_cli; print(hpe_cli.__file__)"]
    return subprocess.run(cmd, env=env, capture_output=True, text=True).stdout.strip()


def main_end_to_end(args, n):

    if not args.skip_kernels:
        kernels(n)
    with tempfile.TemporaryDirectory(dir=args.data) as tmp:
        data = Path(args.data) if args.data else Path(tmp)
        angles, matrix = data / f"angles_{n}.parquet", data / f"matrix_{n}.parquet"
        if not (angles.exists() and matrix.exists()):
            make_angles(angles, n, matrix_path=matrix)
        out = Path(tmp) / "out.parquet"
        width = 1 + len(LABEL_COLS)  # id + pitch..roll, pitch_2.., r00..r22, gimbal_lock, roundtrip_err
        threads = ["--threads", str(args.threads)] if args.threads else []
        print(
            f"end to end, {n:,} rows, Parquet in -> Parquet out; medians of {args.repeat} alternating rounds; "
            "floor = pyarrow reading the input and writing the output's width batch by batch (hpe's encoding)"
        )
        print(f"  hpe: {hpe_source()}")
        for name, inp in (("convert angles", angles), ("convert matrices", matrix)):
            cmd = HPE + ["convert", inp, "-o", out, "--from", "300w_lp", "--to", "scipy_zyx", "-q", "--overwrite"]
            compare(name, cmd + threads, floor_cmd(inp, out, width), args.repeat)


if __name__ == "__main__":
    main()
