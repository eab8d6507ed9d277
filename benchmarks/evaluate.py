"""Throughput of `hpe evaluate` end to end, next to a per-row Python loop and the Parquet read+write floor.

    python benchmarks/evaluate.py [--rows 1000000] [--loop-rows 20000]

End to end: two Parquet tables (string key 'image', pitch/yaw/roll) in
different systems (6drepnet predictions, 300w_lp GT, shuffled so the join has
work to do), every core metric, the protocols asked (default: hopenet,
6drepnet, whenet, opal23), the JSON report and the per-row Parquet out. The
loop computes the same core metrics and those protocols one row at a time
with SciPy (dict join, per-row conversion), on --loop-rows rows, reported as
rows/s. The floor reads both tables and writes one of the same width.
`hpe evaluate` runs as a child process (imports included) and its own peak RSS
is printed (Linux ru_maxrss).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from scipy.spatial.transform import Rotation


def make_tables(n, folder: Path):
    from hpe_cli.rotation import get_system

    rng = np.random.default_rng(0)
    g = np.c_[rng.uniform(-80, 80, n), rng.uniform(-89, 89, n), rng.uniform(-80, 80, n)]
    s300, s6 = get_system("300w_lp"), get_system("6drepnet")
    A = s300.from_angles(g)
    noise = Rotation.from_rotvec(np.deg2rad(rng.normal(0, 5, (n, 3)))).as_matrix()
    p, _, _, _ = s6.to_angles(s6.from_canonical(noise @ A))
    names = np.char.add("img", np.arange(n).astype(str)).astype(object)
    pq.write_table(pa.table({"image": names, "pitch": g[:, 0], "yaw": g[:, 1], "roll": g[:, 2]}), folder / "gt.parquet")
    order = rng.permutation(n)
    pq.write_table(pa.table({"image": names[order], "pitch": p[order, 0], "yaw": p[order, 1], "roll": p[order, 2]}),
                   folder / "pred.parquet")


def per_row_loop(folder: Path, limit: int):
    """The naive method: dict join, one SciPy conversion and one error computation per row."""
    gt = pq.read_table(folder / "gt.parquet").slice(0, limit).to_pylist()
    pred = {r["image"]: r for r in pq.read_table(folder / "pred.parquet").to_pylist()}
    out = []
    for row in gt:
        pr = pred.get(row["image"])
        if pr is None:
            continue
        G = Rotation.from_euler("XYZ", [-row["pitch"], -row["yaw"], -row["roll"]], degrees=True)
        P = Rotation.from_matrix(Rotation.from_euler("xyz", [pr["pitch"], pr["yaw"], pr["roll"]],
                                                     degrees=True).as_matrix().T)
        geo = np.degrees((P * G.inv()).magnitude())
        mp, mg = P.as_matrix(), G.as_matrix()
        maev = [np.degrees(np.arccos(np.clip(mp[:, k] @ mg[:, k], -1, 1))) for k in range(3)]
        fro = np.linalg.norm(mp - mg)
        gp = -G.as_euler("XYZ", degrees=True)
        pp = -P.as_euler("XYZ", degrees=True)
        d = np.abs(pp - gp) % 360
        wrapped = np.minimum(d, 360 - d)
        hop = np.abs(pp - gp)
        six = np.min([np.abs(pp - gp + k) for k in (0, 360, -360, 180, -180)], axis=0)
        out.append((row["image"], *gp, *pp, *wrapped, geo, *maev, fro, *hop, *six))
    cols = list(zip(*out))
    pq.write_table(pa.table({f"c{i}": list(c) for i, c in enumerate(cols)}), folder / "loop.parquet")
    return len(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--loop-rows", type=int, default=20_000)
    ap.add_argument("--protocol", action="append", default=None)
    args = ap.parse_args()
    n = args.rows
    protocols = args.protocol or ["hopenet", "6drepnet", "whenet", "opal23"]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        make_tables(n, folder)
        print(f"hpe evaluate, {n:,} pairs (Parquet in, JSON report + per-row Parquet out), protocols {protocols}")

        t = time.perf_counter()
        c0 = time.process_time()
        a = pq.read_table(folder / "gt.parquet")
        b = pq.read_table(folder / "pred.parquet")
        width = pa.table({f"c{i}": a.column(1) for i in range(16)}).append_column("image", a.column(0))
        pq.write_table(width, folder / "floor.parquet", compression="none", use_dictionary=False)
        t_floor = time.perf_counter() - t
        cpu_floor = time.process_time() - c0
        del a, b, width
        print(f"  {'floor: pyarrow read both + write 17 columns':<52} {n / t_floor / 1e6:8.2f} M rows/s "
              f"({t_floor:6.2f} s, CPU {cpu_floor:.2f} s)")

        # the command itself in a child process (imports included), so its peak RSS is its own
        cmd = [sys.executable, "-m", "hpe_cli", "evaluate", str(folder / "pred.parquet"),
               str(folder / "gt.parquet"), "--pred-system", "6drepnet", "--gt-system", "300w_lp",
               "-o", str(folder / "errors.parquet"), "--json", str(folder / "report.json"), "-q"]
        for p in protocols:
            cmd += ["--protocol", p]
        env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1]) + os.pathsep
               + os.environ.get("PYTHONPATH", "")}
        t = time.perf_counter()
        subprocess.run(cmd, check=True, env=env)
        t_hpe = time.perf_counter() - t
        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        rss_hpe, cpu_hpe = ru.ru_maxrss / 1024, ru.ru_utime + ru.ru_stime
        rep = json.loads((folder / "report.json").read_text())
        assert rep["n"]["pairs"] == n
        print(f"  {'hpe evaluate (join, metrics, protocols, outputs)':<52} {n / t_hpe / 1e6:8.2f} M rows/s "
              f"({t_hpe:6.2f} s)  {t_hpe / t_floor:5.1f}x the floor, CPU {cpu_hpe:.2f} s, "
              f"peak RSS {rss_hpe:,.0f} MB")
        print(f"    geodesic mean {rep['metrics']['geodesic']['mean']:.3f} deg, 6drepnet MAE "
              f"{rep['protocols'].get('6drepnet', {}).get('mean', float('nan')):.3f}")

        m = min(args.loop_rows, n)
        t = time.perf_counter()
        done = per_row_loop(folder, m)
        t_loop = time.perf_counter() - t
        print(f"  {'per-row Python loop (SciPy per row), %d rows' % done:<52} {done / t_loop / 1e6:8.4f} M rows/s "
              f"({t_loop:6.2f} s)  -> hpe is {(n / t_hpe) / (done / t_loop):6.0f}x faster")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"  peak RSS of this benchmark process (table generation, loop) {rss:,.0f} MB")


if __name__ == "__main__":
    main()
