"""`hpe evaluate` at scale: time and peak RSS next to the floor, in the same run.

    python benchmarks/evaluate.py [--rows 2000000] [--protocol NAME ...] [--shuffled] [--json-only]

Two Parquet tables of N pairs (string key 'image', pitch/yaw/roll; GT in
300w_lp, predictions in 6drepnet, the same rotation turned by ~5 degrees).

* floor: pyarrow streams both files batch by batch (the same columns) and
  does a plain numpy pass over them: rotation matrices from the angles and the
  geodesic error, summed. Nothing else (no join, no protocol, no output).
* hpe: ``hpe evaluate`` in a child process (imports included) with the per-row
  Parquet output and the JSON report, predictions in GT order (streamed:
  memory flat in N) or, with --shuffled, in random order (external hash join: both sides partitioned
  by key on disk, joined one partition at a time; memory flat in N too).

Peak RSS is each child's VmHWM (/proc/self/status). Keep N small on a shared
machine (2M pairs take about a minute); the issue's target is 30M pairs with
peak RSS < 1 GB and time within 1.5x of the floor.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]


def make_tables(n, folder: Path, shuffled: bool, chunk=1_000_000):
    """Write gt.parquet and pred.parquet chunk by chunk (the generator's own memory stays small).

    ``shuffled``: the prediction rows of each chunk in random order and the chunks written in random order
    (no key is where the GT has it; written in flat memory, so 30M pairs can be generated too)."""
    from scipy.spatial.transform import Rotation

    sys.path.insert(0, str(ROOT))
    from hpe_cli.rotation import get_system

    s300, s6 = get_system("300w_lp"), get_system("6drepnet")
    starts = list(range(0, n, chunk))
    order = np.random.default_rng(1).permutation(len(starts)) if shuffled else np.arange(len(starts))
    gw = pw = None
    for a in starts:
        m = min(chunk, n - a)
        rng = np.random.default_rng(a)
        g = np.c_[rng.uniform(-80, 80, m), rng.uniform(-89, 89, m), rng.uniform(-80, 80, m)]
        names = pa.array(np.char.add("img", np.arange(a, a + m).astype(str)).astype(object), pa.string())
        gt = pa.table({"image": names, "pitch": g[:, 0], "yaw": g[:, 1], "roll": g[:, 2]})
        gw = gw or pq.ParquetWriter(folder / "gt.parquet", gt.schema)
        gw.write_table(gt)
    for c in order:
        a = starts[c]
        m = min(chunk, n - a)
        rng = np.random.default_rng(a)
        g = np.c_[rng.uniform(-80, 80, m), rng.uniform(-89, 89, m), rng.uniform(-80, 80, m)]
        noise = Rotation.from_rotvec(np.deg2rad(rng.normal(0, 3, (m, 3)))).as_matrix()
        p, _, _, _ = s6.to_angles(s6.from_canonical(noise @ s300.from_angles(g)))
        names = pa.array(np.char.add("img", np.arange(a, a + m).astype(str)).astype(object), pa.string())
        pr = pa.table({"image": names, "pitch": p[:, 0], "yaw": p[:, 1], "roll": p[:, 2]})
        if shuffled:
            pr = pr.take(pa.array(rng.permutation(m)))
        pw = pw or pq.ParquetWriter(folder / "pred.parquet", pr.schema)
        pw.write_table(pr)
    gw.close()
    pw.close()


FLOOR = textwrap.dedent("""
    import sys, numpy as np, pyarrow.parquet as pq
    def mats(p, y, r):  # 300W-LP A = Rx(p).T Ry(y).T Rz(r).T, column by column
        cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
        return [cy * cr, cy * sr, -sy, sp * sy * cr - cp * sr, sp * sy * sr + cp * cr, sp * cy,
                cp * sy * cr + sp * sr, cp * sy * sr - sp * cr, cp * cy]
    a, b = pq.ParquetFile(sys.argv[1]), pq.ParquetFile(sys.argv[2])
    cols = ["image", "pitch", "yaw", "roll"]
    total, n = 0.0, 0
    for x, y in zip(a.iter_batches(262144, columns=cols), b.iter_batches(262144, columns=cols)):
        A = mats(*(np.radians(x.column(k).to_numpy()) for k in (1, 2, 3)))
        B = mats(*(np.radians(y.column(k).to_numpy()) for k in (1, 2, 3)))
        x.column(0), y.column(0)
        tr = sum(A[k] * B[k] for k in range(9))
        total += np.degrees(np.arccos(np.clip((tr - 1) / 2, -1, 1))).sum()
        n += x.num_rows
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
    print(n, total / n, int(hwm) // 1024)
""")

HPE = textwrap.dedent("""
    import sys
    from hpe_cli.cli.main import cli
    try:
        cli.main(sys.argv[1:], standalone_mode=False)
    finally:
        hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
        print("VmHWM_MB", int(hwm) // 1024, file=sys.stderr)
""")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument(
        "--protocol",
        action="append",
        default=None,
        help="protocols to run (default: 6drepnet360); 'all' for every protocol",
    )
    ap.add_argument("--shuffled", action="store_true", help="predictions in random order (external hash join)")
    ap.add_argument("--json-only", action="store_true", help="skip the run that also writes the per-row output")
    args = ap.parse_args()
    n = args.rows
    protocols = args.protocol or ["6drepnet360"]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        make_tables(n, folder, args.shuffled)
        print(
            f"hpe evaluate, {n:,} pairs, predictions {'shuffled' if args.shuffled else 'in GT order'}, "
            f"protocols {protocols}"
        )
        t = time.perf_counter()
        out = subprocess.run(
            [sys.executable, "-c", FLOOR, str(folder / "gt.parquet"), str(folder / "pred.parquet")],
            check=True,
            capture_output=True,
            text=True,
            env=env,
        ).stdout.split()
        t_floor = time.perf_counter() - t
        print(
            f"  floor (pyarrow stream + numpy geodesic)  {t_floor:7.2f} s  {n / t_floor / 1e6:6.2f} M pairs/s  "
            f"peak RSS {int(out[2]):,} MB  (geodesic mean {float(out[1]):.3f})"
        )
        runs = (
            ("hpe evaluate --json", []),
            ("hpe evaluate --json -o rows.parquet", ["-o", str(folder / "errors.parquet")]),
        )
        for label, extra in runs[:1] if args.json_only else runs:
            cmd = [
                sys.executable,
                "-c",
                HPE,
                "evaluate",
                str(folder / "pred.parquet"),
                str(folder / "gt.parquet"),
                "--pred-system",
                "6drepnet",
                "--gt-system",
                "300w_lp",
                "--json",
                str(folder / "report.json"),
                "-q",
                "--overwrite",
                *extra,
            ]
            if "all" not in protocols:
                for p in protocols:
                    cmd += ["--protocol", p]
            t = time.perf_counter()
            r = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
            t_hpe = time.perf_counter() - t
            hwm = int(r.stderr.split("VmHWM_MB")[1].split()[0])
            rep = json.loads((folder / "report.json").read_text())
            assert rep["n"]["pairs"] == n, rep["n"]
            g = rep["metrics"]["geodesic"]
            print(
                f"  {label:<40} {t_hpe:7.2f} s  {n / t_hpe / 1e6:6.2f} M pairs/s  peak RSS {hwm:,} MB  "
                f"({t_hpe / t_floor:.2f}x the floor; {rep['inputs']['paired']}; geodesic mean {g['mean']:.3f}, "
                f"median {g['median']:.3f})"
            )


if __name__ == "__main__":
    main()
