"""Throughput of ``hpe audit``: the vectorised job on 1M rows vs a naive per-row loop on a subset.

Usage::

    python benchmarks/audit.py                 # 1,000,000 rows, Parquet and CSV
    python benchmarks/audit.py --rows 200000 --baseline-rows 5000
    python benchmarks/audit.py --rows 10000000 --floor-only [--repeat 3] [--threads N] [--data DIR] [--before DIR]

``--floor-only`` runs only the comparison with the read floor (issue 33: <= 2x, <= 400 MB at 10M rows):
``hpe audit FILE --json R`` on ``id, pitch, yaw, roll`` (the table of ``benchmarks/convert.py``) against
pyarrow reading the same file batch by batch, each its own process under GNU time, medians of alternating
rounds (``benchmarks/streaming.py``); without it, that comparison ends the run. ``--before DIR`` (a checkout or
``git archive`` of another version, with its ``_hpe_kernels`` built there: ``python setup.py build_ext
--inplace``) adds rounds alternating this checkout's audit with that one's, the medians side by side and
whether their JSON reports are the same bytes.

Prints rows/s for: the end-to-end job (read, check, hash for duplicates, JSON
report) on Parquet and CSV, the same with ``-o`` and ``--plots``, and the
naive baseline (one ``from_angles``/``to_angles`` call and a Python set
lookup per row) run in the same process. The counts of both must agree on
the subset.
"""

from __future__ import annotations

import argparse
import compileall
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd


def make_table(n: int, seed: int = 0) -> pd.DataFrame:
    """Random 300W-LP-like labels with a sprinkle of every problem the audit looks for."""
    rng = np.random.default_rng(seed)
    df = pd.DataFrame(
        {
            "image": [f"img{i:08d}.jpg" for i in range(n)],
            "pitch": rng.normal(0, 25, n).clip(-89, 89),
            "yaw": rng.uniform(-99, 99, n),
            "roll": rng.normal(0, 15, n),
        }
    )
    k = max(1, n // 1000)
    idx = rng.choice(n, size=4 * k, replace=False)
    df.loc[idx[:k], "yaw"] = 89.99858  # gimbal lock
    df.loc[idx[k : 2 * k], "pitch"] = np.nan  # non-finite
    df.loc[idx[2 * k : 3 * k], "roll"] = 200.0  # out of range
    src = idx[3 * k :]
    dst = (src + 1) % n
    df.loc[dst, ["image", "pitch", "yaw", "roll"]] = df.loc[src, ["image", "pitch", "yaw", "roll"]].to_numpy()
    return df


def naive_audit(df: pd.DataFrame, system, near_tol_deg: float = 1.0) -> dict:
    """One row at a time: what a straightforward loop would do (the baseline)."""
    from hpe_cli.rotation.euler import wrap_180

    counts = dict.fromkeys(
        ["gimbal_lock", "near_gimbal", "non_canonical", "out_of_range", "non_finite", "not_rotation", "duplicates"], 0
    )
    seen = set()
    sin_tol = np.sin(np.deg2rad(near_tol_deg))
    for img, p, y, r in df[["image", "pitch", "yaw", "roll"]].itertuples(index=False):
        key = (img, p + 0.0, y + 0.0, r + 0.0) if np.isfinite([p, y, r]).all() else (img, str(p), str(y), str(r))
        if key in seen:
            counts["duplicates"] += 1
        seen.add(key)
        if not np.isfinite([p, y, r]).all():
            counts["non_finite"] += 1
            continue
        pyr = np.array([[p, y, r]])
        prim, _, locked, lock = system.to_angles(system.from_angles(pyr))
        counts["gimbal_lock"] += int(locked[0])
        counts["near_gimbal"] += int(locked[0] or lock[0] < sin_tol)
        d = np.abs(wrap_180(pyr[0]) - prim[0])
        if not locked[0] and np.minimum(d, 360 - d).max() > 1e-6:
            counts["non_canonical"] += 1
        out = any(v <= -180 or v > 180 for v in (p, y, r)) or not system.in_range(pyr)[0]
        counts["out_of_range"] += int(out)
    return counts


def timed(label, n, fn):
    t0 = time.perf_counter()
    out = fn()
    dt = time.perf_counter() - t0
    print(f"{label:<44} {n:>10,d} rows {dt:8.2f} s {n / dt:>14,.0f} rows/s", flush=True)
    return out, dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--baseline-rows", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=3, help="alternating rounds of hpe and floor (medians)")
    ap.add_argument("--threads", type=int, default=None, help="hpe audit --threads (default: its own)")
    ap.add_argument("--data", default=None, help="folder keeping the generated input between runs")
    ap.add_argument("--floor-only", action="store_true", help="only the comparison with the read floor")
    ap.add_argument("--before", default=None, help="another checkout's folder: its audit in the same rounds")
    args = ap.parse_args(argv)
    if args.floor_only:
        return floor_comparison(args)
    same = in_process(args)
    floor_comparison(args)
    return 0 if same else 1


def floor_comparison(args) -> int:
    """``hpe audit`` against the streaming read floor (medians, ratios, peak RSS)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from streaming import HPE, compare, floor_cmd, make_angles

    n = args.rows
    # run from this checkout: ``python -c`` puts the working folder first on sys.path, so a run started in
    # another checkout would time that checkout's hpe_cli whatever PYTHONPATH says
    data = str(Path(args.data).resolve()) if args.data else None
    os.chdir(Path(__file__).resolve().parents[1])
    # hpe's bytecode, as an installed package has it (PYTHONDONTWRITEBYTECODE would leave every run compiling
    # hpe_cli from source, 0.25 s that the floor, reading pyarrow's compiled modules, does not pay)
    compileall.compile_dir(Path(__file__).resolve().parents[1] / "hpe_cli", quiet=1)
    with tempfile.TemporaryDirectory(dir=data) as tmp:
        angles = (Path(data) if data else Path(tmp)) / f"angles_{n}.parquet"
        if not angles.exists():
            make_angles(angles, n)
        threads = ["--threads", str(args.threads)] if args.threads else []
        print(
            f"{n:,} rows (id, pitch, yaw, roll), Parquet; medians of {args.repeat} alternating rounds; "
            "floor = pyarrow reading the file batch by batch"
        )
        cmd = HPE + ["audit", angles, "--json", Path(tmp) / "r.json", "-q", "--overwrite"] + threads
        compare("audit (JSON report)", cmd, floor_cmd(angles, Path(tmp) / "unused", 0), args.repeat)
        if args.before:
            before = HPE + ["audit", angles, "--json", Path(tmp) / "b.json", "-q", "--overwrite"] + threads
            before_comparison(cmd, before, Path(args.before).resolve(), args.repeat)
            same = (Path(tmp) / "r.json").read_bytes() == (Path(tmp) / "b.json").read_bytes()
            print(f"  JSON reports of this checkout and --before: {'the same bytes' if same else 'DIFFERENT'}")
    return 0


def before_comparison(cmd, before_cmd, before: Path, repeat: int) -> None:
    """This checkout's ``cmd`` and ``before_cmd`` run from the folder ``before`` (its ``hpe_cli`` first on the path)
    in alternating rounds under GNU time: medians of wall, CPU and peak RSS side by side."""
    import statistics
    import subprocess

    def one(c, folder: Path):
        env = {**os.environ, "PYTHONPATH": str(folder)}
        res = subprocess.run(
            ["/usr/bin/time", "-f", "@@%e %U %S %M"] + [str(x) for x in c],
            cwd=folder,
            env=env,
            text=True,
            capture_output=True,
        )
        if res.returncode != 0:
            raise SystemExit(f"failed in {folder} ({res.returncode}):\n{res.stderr[-2000:]}")
        wall, user, system, kb = [ln for ln in res.stderr.splitlines() if ln.startswith("@@")][-1][2:].split()
        return float(wall), float(user) + float(system), int(kb) / 1024

    root = Path(__file__).resolve().parents[1]
    compileall.compile_dir(before / "hpe_cli", quiet=1)  # bytecode, as for this checkout
    runs = {"now": [], "before": []}
    for _ in range(repeat):
        runs["now"].append(one(cmd, root))
        runs["before"].append(one(before_cmd, before))
    med = {k: [statistics.median(r[i] for r in v) for i in range(3)] for k, v in runs.items()}
    (nw, nc, nm), (bw, bc, bm) = med["now"], med["before"]
    print(
        f"  {'audit, this checkout / before':<30} {nw:6.2f} / {bw:6.2f} s wall, cpu {nc:6.2f} / {bc:6.2f} s, "
        f"{nm:4.0f} / {bm:4.0f} MB   ratio {nw / bw:4.2f} (cpu {nc / bc:4.2f})   load {os.getloadavg()[0]:.1f}",
        flush=True,
    )


def in_process(args) -> bool:

    from hpe_cli.pipelines.audit import AuditOptions, run_audit
    from hpe_cli.rotation import get_system

    system = get_system("300w_lp")
    keys = ["gimbal_lock", "near_gimbal", "non_canonical", "out_of_range", "non_finite", "not_rotation", "duplicates"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        df = make_table(args.rows)
        df.to_parquet(tmp / "big.parquet", index=False)
        df.to_csv(tmp / "big.csv", index=False)
        rep, _ = timed(
            "hpe audit parquet (json report)",
            args.rows,
            lambda: run_audit(tmp / "big.parquet", system, AuditOptions(report=tmp / "r1.json")),
        )
        timed(
            "hpe audit csv (json report)",
            args.rows,
            lambda: run_audit(tmp / "big.csv", system, AuditOptions(report=tmp / "r2.json")),
        )
        timed(
            "hpe audit parquet (+ -o flags.parquet, --plots)",
            args.rows,
            lambda: run_audit(tmp / "big.parquet", system, AuditOptions(output=tmp / "f.parquet", plots=tmp / "plots")),
        )
        print("  counts:", {k: rep[k] for k in keys})

        sub = df.iloc[: args.baseline_rows]
        sub.to_parquet(tmp / "sub.parquet", index=False)
        naive, t_naive = timed("naive per-row loop (baseline)", len(sub), lambda: naive_audit(sub, system))
        fast, t_fast = timed("hpe audit on the same subset", len(sub), lambda: run_audit(tmp / "sub.parquet", system))
        same = all(naive[k] == fast[k] for k in keys)
        print(f"  subset counts agree: {same}; speed-up {t_naive / t_fast:,.0f}x")
        return same


if __name__ == "__main__":
    sys.exit(main())
