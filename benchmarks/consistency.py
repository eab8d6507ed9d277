"""Throughput of ``hpe audit --consistency`` on 68-point rows, beside its floors, with peak RSS.

Usage::

    python benchmarks/consistency.py                 # 500,000 rows
    python benchmarks/consistency.py --rows 100000
    python benchmarks/consistency.py --rows 10000000 --table /tmp/lm68_10M.parquet --only-cli
                                                     # keep the table for the next run; CLI runs only
    python benchmarks/consistency.py --rows 1000000 --frames --only-cli
                                                     # with sequence, camera, frame columns (time check)

A synthetic table (image, pitch/yaw/roll, 68 landmark pairs = 136 float columns,
the landmarks projected from the 68-point template with the label plus 1 px
noise, 5% of the labels turned by 30 deg) is written as Parquet. Printed, in the
same run:

- the landmark kernel alone (:func:`hpe_cli.geometry.landmark_pose.fit_landmark_pose`
  on in-memory arrays, one core), rows/s;
- floor: reading the 139 columns with pyarrow, rows/s;
- floor: ``hpe audit`` without ``--consistency`` (its own checks), rows/s;
- ``hpe audit --consistency --json``, rows/s and peak RSS of that process;
- how many of the turned rows are suspects (all of them should be).

Each CLI run is a separate process (``/usr/bin/time``-free: peak RSS from
``resource.getrusage(RUSAGE_CHILDREN)`` of a fresh child each time).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def make_table(n: int, path: Path, seed: int = 0, frames: bool = False) -> int:
    import pyarrow as pa
    import pyarrow.parquet as pq
    from scipy.spatial.transform import Rotation

    from hpe_cli.geometry.landmark_pose import project_model
    from hpe_cli.rotation.systems import get_system

    rng = np.random.default_rng(seed)
    s = get_system("300w_lp")
    writer = None
    turned = 0
    chunk = 100_000
    for start in range(0, n, chunk):
        m = min(chunk, n - start)
        if frames:  # one head seen by 10 cameras, turning slowly: rows sorted by frame
            f = (start + np.arange(m)) // 10
            pyr = np.stack([10 * np.sin(f / 37), 60 * np.sin(f / 50), 5 * np.cos(f / 23)], 1)
        else:
            pyr = np.stack([rng.normal(0, 15, m), rng.uniform(-80, 80, m), rng.normal(0, 10, m)], 1)
        A = s.to_canonical(s.from_angles(pyr))
        uv = project_model(A, np.full(m, 120.0), np.full((m, 2), 225.0), "ibug68")
        uv += rng.normal(0, 1.0, uv.shape)
        uv = np.nan_to_num(uv, nan=225.0)  # jaw points: any value (not used by the fit)
        bad = rng.random(m) < 0.05
        turned += int(bad.sum())
        T = Rotation.from_rotvec(np.deg2rad(30) * np.array([0.0, 1.0, 0.0])).as_matrix()
        A[bad] = T @ A[bad]
        lab = s.to_angles(s.from_canonical(A))[0]
        cols = {"image": pa.array([f"img{start + i:08d}.jpg" for i in range(m)])}
        if frames:
            cols["sequence"] = pa.array(np.full(m, "s0"))
            cols["camera"] = pa.array([f"00_{c:02d}" for c in (start + np.arange(m)) % 10])
            cols["frame"] = pa.array((start + np.arange(m)) // 10)
        for k, c in enumerate(("pitch", "yaw", "roll")):
            cols[c] = pa.array(lab[:, k])
        for i in range(68):
            cols[f"lm{i}_x"] = pa.array(uv[:, i, 0])
            cols[f"lm{i}_y"] = pa.array(uv[:, i, 1])
        t = pa.table(cols)
        if writer is None:
            writer = pq.ParquetWriter(path, t.schema)
        writer.write_table(t)
    writer.close()
    Path(f"{path}.turned").write_text(str(turned))  # for a later run that reuses the table
    return turned


def run_cli(args) -> tuple[float, float, str]:
    """Seconds, peak RSS (MB) and stdout of ``python -m hpe_cli ARGS`` in a fresh child process."""
    code = (
        "import resource, subprocess, sys, time;"
        "t=time.perf_counter();"
        f"r=subprocess.run([sys.executable, '-m', 'hpe_cli', *{args!r}], capture_output=True, text=True);"
        "dt=time.perf_counter()-t;"
        "rss=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss/1024;"
        "sys.stderr.write(r.stderr);"
        "print(dt, rss); print(r.stdout)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=os.environ)
    if out.returncode:
        raise SystemExit(out.stderr)
    first, _, rest = out.stdout.partition("\n")
    dt, rss = map(float, first.split())
    return dt, rss, rest


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=500_000)
    ap.add_argument("--table", help="Parquet file of the table: made when missing, reused (same --rows) when present")
    ap.add_argument("--only-cli", action="store_true", help="skip the kernel and the pyarrow floor")
    ap.add_argument(
        "--frames", action="store_true", help="sequence/camera/frame columns (10 cameras, sorted): the time check runs"
    )
    a = ap.parse_args(argv)
    n = a.rows
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(a.table) if a.table else Path(tmp) / "lm68.parquet"
        if path.exists():
            import pyarrow.parquet as pq

            if pq.ParquetFile(path).metadata.num_rows != n:
                raise SystemExit(f"{path}: has {pq.ParquetFile(path).metadata.num_rows} rows, expected --rows {n}")
            turned = int(Path(f"{path}.turned").read_text())
        else:
            turned = make_table(n, path, frames=a.frames)
        print(
            f"{n:,} rows of 68 landmarks ({path.stat().st_size / 1e6:.0f} MB Parquet); {turned:,} labels turned 30 deg"
        )
        if not a.only_cli:
            floors(path, n)
        cli_runs(path, n, turned, Path(tmp))


def floors(path: Path, n: int) -> None:
    """The landmark kernel in memory (200,000 rows) and the pyarrow read of the columns (streamed)."""
    import pyarrow.parquet as pq

    from hpe_cli.geometry.landmark_pose import fit_landmark_pose

    t = pq.read_table(path, columns=[f"lm{i}_{c}" for i in range(68) for c in "xy"]).slice(0, 200_000)
    uv = np.stack([t.column(f"lm{i}_{c}").to_numpy() for i in range(68) for c in "xy"], 1).reshape(-1, 68, 2)
    fit_landmark_pose(uv[:1000], "ibug68")
    t0 = time.perf_counter()
    for s in range(0, len(uv), 65_536):
        fit_landmark_pose(uv[s : s + 65_536], "ibug68")
    dt = time.perf_counter() - t0
    print(f"landmark kernel (fit_landmark_pose, in memory): {len(uv) / dt:12,.0f} rows/s")

    del t, uv
    t0 = time.perf_counter()
    names = ["pitch", "yaw", "roll"] + [f"lm{i}_{c}" for i in range(68) for c in "xy"]
    for _ in pq.ParquetFile(path).iter_batches(65_536, columns=names):  # streamed: flat memory at 10M rows
        pass
    dt = time.perf_counter() - t0
    print(f"floor: pyarrow read of the 139 columns:         {n / dt:12,.0f} rows/s")


def cli_runs(path: Path, n: int, turned: int, tmp: Path) -> None:
    """``hpe audit`` without and with ``--consistency``, each in a fresh process."""
    dt, rss, _ = run_cli(["audit", str(path), "--json", str(Path(tmp) / "a.json"), "-q"])
    print(f"floor: hpe audit (no --consistency):            {n / dt:12,.0f} rows/s  peak RSS {rss:,.0f} MB")

    dt, rss, _ = run_cli(["audit", str(path), "--consistency", "--json", str(Path(tmp) / "c.json"), "-q"])
    rep = json.loads((Path(tmp) / "c.json").read_text())["consistency"]
    print(f"hpe audit --consistency:                        {n / dt:12,.0f} rows/s  peak RSS {rss:,.0f} MB")
    print(
        f"  checked {rep['checked']:,}, suspects {rep['suspects']:,} (turned {turned:,}); "
        f"landmark angle median {rep['landmarks']['angle_deg']['median']} deg"
    )
    print(f"  cores: {os.cpu_count()} (the job's numpy work runs on the audit's worker threads)")


if __name__ == "__main__":
    main()
