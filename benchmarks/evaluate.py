"""`hpe evaluate` at scale: time and peak RSS beside DuckDB and the floor, in the same run.

    python benchmarks/evaluate.py [--rows 5000000] [--shuffled] [--protocol NAME ...] [--repeat 3]
        [--threads N] [--with-rows] [--join] [--each-protocol] [--exact-floor] [--before DIR] [--data DIR]

Two Parquet tables of N pairs (string key 'image', pitch/yaw/roll; GT in
300w_lp, predictions in 6drepnet, the same rotation turned by about 5 degrees:
a rotation vector with N(0, 3 deg) components), predictions in GT order or,
with --shuffled, in random order.

* DuckDB: the job a user would write in SQL: join on ``image``, both rotation
  matrices from the angles, the geodesic angle (``acos`` of the trace), the
  per-angle MAE and the median geodesic error, on DuckDB's own threads. A
  benchmark dependency only (``pip install duckdb``, or the ``bench`` extra;
  skipped when absent).
* floor: pyarrow streams both files batch by batch (the same columns) and
  does a plain numpy pass over them: rotation matrices from the angles and the
  geodesic error, summed. No join, no protocol, no output.
* hpe: ``hpe evaluate`` in a child process (imports included) writing the JSON
  report (``--with-rows``: also the per-row Parquet output); ``--protocol all``
  (the command's default) scores every protocol, the default here is hopenet.
* ``--each-protocol``: one hpe job per protocol and one with all of them, side by side (a per-protocol table).
* ``--exact-floor`` (with ``--protocol all``): what every protocol costs at least while each keeps its peer's
  arithmetic: the ``--protocol hopenet`` run (timed in the same rounds) plus the C library calls
  (``atan2``, ``hypot``, ``acos``, ``asin``, ``sincos``...) that the other protocols add, counted by
  ``benchmarks/libm.py``'s shim in one run of each outside the timed rounds, at this machine's scalar cost per
  call, spread over its cores. The default run is printed as a multiple of that floor.
* ``--join``: the same minimal job (join on the key, geodesic, per-angle MAE,
  median) done by pyarrow's ``Table.join`` (Acero, in memory), beside hpe's
  join and DuckDB's.

Each child's peak RSS is its VmHWM (/proc/self/status), its CPU time the user + system time of all its threads
(``getrusage(RUSAGE_CHILDREN)``: on a shared machine the CPU ratio moves less than the wall ratio). Each job runs --repeat
times, the jobs taking turns; the median is printed with the range in brackets.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
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


DUCKDB = textwrap.dedent(r'''
    import sys, duckdb
    con = duckdb.connect()
    con.execute("SET enable_progress_bar = false")
    if sys.argv[3] != "0":
        con.execute(f"SET threads = {int(sys.argv[3])}")
    def mat(p, y, r):  # 300W-LP A = Rx(p).T Ry(y).T Rz(r).T, entry by entry (radians)
        cp, sp, cy, sy, cr, sr = (f"{f}({v})" for v in (p, y, r) for f in ("cos", "sin"))
        return [f"{cy}*{cr}", f"{cy}*{sr}", f"-{sy}", f"{sp}*{sy}*{cr} - {cp}*{sr}", f"{sp}*{sy}*{sr} + {cp}*{cr}",
                f"{sp}*{cy}", f"{cp}*{sy}*{cr} + {sp}*{sr}", f"{cp}*{sy}*{sr} - {sp}*{cr}", f"{cp}*{cy}"]
    trace = " + ".join(f"({a})*({b})" for a, b in zip(mat("gp", "gy", "gr"), mat("pp", "py", "pr")))
    q = f"""
        WITH j AS (
            SELECT radians(g.pitch) gp, radians(g.yaw) gy, radians(g.roll) gr,
                   radians(p.pitch) pp, radians(p.yaw) py, radians(p.roll) pr,
                   abs(g.pitch - p.pitch) ep, abs(g.yaw - p.yaw) ey, abs(g.roll - p.roll) er
            FROM read_parquet('{sys.argv[1]}') g JOIN read_parquet('{sys.argv[2]}') p USING (image)),
        e AS (SELECT degrees(acos(greatest(-1.0, least(1.0, (({trace}) - 1) / 2)))) geo, ep, ey, er FROM j)
        SELECT count(*), avg(geo), median(geo), avg(ep), avg(ey), avg(er) FROM e"""
    n, mean, med, ep, ey, er = con.execute(q).fetchone()
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
    print(n, mean, med, int(hwm) // 1024)
''')

ACERO = textwrap.dedent("""
    import sys, numpy as np, pyarrow.parquet as pq
    def mats(p, y, r):
        cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
        return [cy * cr, cy * sr, -sy, sp * sy * cr - cp * sr, sp * sy * sr + cp * cr, sp * cy,
                cp * sy * cr + sp * sr, cp * sy * sr - sp * cr, cp * cy]
    cols = ["image", "pitch", "yaw", "roll"]
    g = pq.read_table(sys.argv[1], columns=cols)
    p = pq.read_table(sys.argv[2], columns=cols).rename_columns(["image", "pp", "py", "pr"])
    j = g.join(p, "image", join_type="inner", use_threads=True)
    del g, p
    a = [j.column(k).to_numpy() for k in ("pitch", "yaw", "roll", "pp", "py", "pr")]
    A, B = mats(*(np.radians(x) for x in a[:3])), mats(*(np.radians(x) for x in a[3:]))
    geo = np.degrees(np.arccos(np.clip((sum(A[k] * B[k] for k in range(9)) - 1) / 2, -1, 1)))
    mae = [np.abs(a[k] - a[k + 3]).mean() for k in range(3)]
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
    print(len(geo), geo.mean(), np.median(geo), int(hwm) // 1024)
""")


def _child(args, env, parse, cwd):
    """``((wall seconds, CPU seconds), parsed output)`` of one child process (CPU: user + system, all threads)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    # from the run's temp folder: ``python -c`` puts the working folder first on sys.path, so run from the checkout
    # every child would import that checkout's hpe_cli whatever PYTHONPATH says (--before)
    r = subprocess.run([sys.executable, "-c", *args], check=True, capture_output=True, text=True, env=env, cwd=cwd)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return (wall, cpu), parse(r)


def _last(r) -> str:
    """The last line a child printed (its result)."""
    return r.stdout.strip().splitlines()[-1]


def _hpe_cmd(folder: Path, protocols, threads, with_rows: bool):
    cmd = [HPE, "evaluate", str(folder / "pred.parquet"), str(folder / "gt.parquet"), "--pred-system", "6drepnet"]
    cmd += ["--gt-system", "300w_lp", "--json", str(folder / "report.json"), "-q", "--overwrite"]
    if with_rows:
        cmd += ["-o", str(folder / "errors.parquet")]
    if "all" not in protocols:
        for p in protocols:
            cmd += ["--protocol", p]
    if threads:
        cmd += ["--threads", str(threads)]
    return cmd


def _summary(label, times, rss, n, ref=None, extra=""):
    """One line: median wall time [range], pairs/s, peak RSS, median CPU time; ratios to ``ref`` = DuckDB's
    ``(wall, cpu)`` medians. Returns this job's ``(wall, cpu)`` medians."""
    walls, cpus = [t[0] for t in times], [t[1] for t in times]
    med, cpu = statistics.median(walls), statistics.median(cpus)
    rng = f"[{min(walls):.2f}-{max(walls):.2f}]" if len(walls) > 1 else ""
    ratio = f"{med / ref[0]:5.2f}x DuckDB (CPU {cpu / ref[1]:5.2f}x)" if ref else ""
    print(
        f"  {label:<46} {med:7.2f} s {rng:<13} {n / med / 1e6:5.2f} M pairs/s  CPU {cpu:7.2f} s  "
        f"peak RSS {max(rss):>6,} MB  {ratio}  {extra}"
    )
    return med, cpu


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=5_000_000)
    ap.add_argument(
        "--protocol", action="append", default=None, help="hpe protocols (default hopenet); 'all': every one"
    )
    ap.add_argument("--shuffled", action="store_true", help="predictions in random order (key join)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each job (the median is printed)")
    ap.add_argument("--threads", type=int, default=0, help="hpe --threads and DuckDB's threads (0: their default)")
    ap.add_argument("--with-rows", action="store_true", help="hpe also writes the per-row Parquet output (-o)")
    ap.add_argument("--join", action="store_true", help="also pyarrow's Table.join (Acero) doing DuckDB's job")
    ap.add_argument("--no-floor", action="store_true", help="skip the pyarrow + numpy floor")
    ap.add_argument(
        "--exact-floor",
        action="store_true",
        help="with --protocol all: also the floor of exact arithmetic (the hopenet run plus the other protocols' "
        "C library calls, counted with benchmarks/libm.py)",
    )
    ap.add_argument(
        "--each-protocol",
        action="store_true",
        help="one hpe job per protocol (every registered one, or those given with --protocol) and one with all "
        "of them: a per-protocol table beside DuckDB",
    )
    ap.add_argument(
        "--before",
        metavar="DIR",
        default=None,
        help="also run every hpe job on the hpe_cli package found in DIR (e.g. an earlier commit's `git archive`), "
        "in the same rounds: before and after side by side",
    )
    ap.add_argument(
        "--data",
        metavar="DIR",
        default=None,
        help="keep the generated files in DIR/<rows>-<order>/ and reuse them in later runs (default: a temporary "
        "folder, removed at the end)",
    )
    args = ap.parse_args()
    n = args.rows
    protocols = args.protocol or ["hopenet"]
    if args.each_protocol:
        sys.path.insert(0, str(ROOT))
        from hpe_cli.metrics.protocols import PROTOCOLS

        singles = [p for p in (args.protocol or list(PROTOCOLS)) if p != "all"]
        hpe_jobs = {f"hpe {p}": [p] for p in singles} | {"hpe all": ["all"]}
    else:
        hpe_jobs = {"hpe": protocols}
    if args.exact_floor and "all" in protocols and "hpe hopenet" not in hpe_jobs:
        hpe_jobs["hpe hopenet"] = ["hopenet"]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    env_before = {**os.environ, "PYTHONPATH": str(args.before or ROOT)}
    try:
        import duckdb  # noqa: F401

        have_duckdb = True
    except ImportError:
        have_duckdb = False
        print("duckdb is not installed (pip install duckdb): its rows are skipped")
    # byte-compile hpe once, as an installed package is (with PYTHONDONTWRITEBYTECODE set, every child would
    # compile the sources it imports again: about 0.4 s a run)
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "hpe_cli")], check=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if args.data:
            folder = Path(args.data) / f"{n}-{'shuffled' if args.shuffled else 'ordered'}"
            folder.mkdir(parents=True, exist_ok=True)
        if not (folder / "complete").is_file():  # a run stopped while writing them writes them again
            make_tables(n, folder, args.shuffled)
            (folder / "complete").write_text("")
        gt, pred = str(folder / "gt.parquet"), str(folder / "pred.parquet")
        print(
            f"{n:,} pairs, predictions {'shuffled' if args.shuffled else 'in GT order'}, hpe protocols {protocols}, "
            f"{os.cpu_count()} cores, median of {args.repeat}"
        )
        jobs = {}
        if have_duckdb:
            jobs["duckdb"] = ([DUCKDB, gt, pred, str(args.threads)], lambda r: _last(r).split())
        if args.join:
            jobs["acero"] = ([ACERO, gt, pred], lambda r: _last(r).split())
        if not args.no_floor:
            jobs["floor"] = ([FLOOR, gt, pred], lambda r: [*_last(r).split()[:2], 0, _last(r).split()[2]])

        def hpe_parse(r):
            rep = json.loads((folder / "report.json").read_text())
            assert rep["n"]["pairs"] == n, rep["n"]
            g = rep["metrics"]["geodesic"]
            return [rep["n"]["pairs"], g["mean"], g["median"], int(r.stderr.split("VmHWM_MB")[1].split()[0])]

        for k, ps in hpe_jobs.items():
            jobs[k] = (_hpe_cmd(folder, ps, args.threads, args.with_rows), hpe_parse)
            if args.before:
                jobs[f"{k} (before)"] = jobs[k]
        times = {k: [] for k in jobs}
        out: dict = {k: [] for k in jobs}
        for _ in range(args.repeat):
            for k, (a, parse) in jobs.items():
                t, o = _child(a, env_before if k.endswith("(before)") else env, parse, folder)
                times[k].append(t)
                out[k].append(o)
        rss = {k: [int(o[3]) for o in v] for k, v in out.items()}
        geo = {k: f"geodesic mean {float(v[0][1]):.6f}, median {float(v[0][2]):.6f}" for k, v in out.items()}
        ref = None
        if have_duckdb:
            ref = _summary(
                "DuckDB (join, geodesic, MAE, median)", times["duckdb"], rss["duckdb"], n, None, geo["duckdb"]
            )
        if args.join:
            _summary("pyarrow Table.join + numpy (in memory)", times["acero"], rss["acero"], n, ref, geo["acero"])
        if not args.no_floor:
            _summary("floor (pyarrow stream + numpy, no join)", times["floor"], rss["floor"], n, ref)
        for k, ps in hpe_jobs.items():
            label = f"hpe evaluate{' -o' if args.with_rows else ''} --protocol {','.join(ps)}"
            _summary(label, times[k], rss[k], n, ref, geo[k])
            if args.before:
                _summary(
                    "  the same, before", times[f"{k} (before)"], rss[f"{k} (before)"], n, ref, geo[f"{k} (before)"]
                )
        if args.exact_floor and "all" in protocols:
            every = "hpe all" if "hpe all" in times else "hpe"
            _exact_floor(
                gt,
                pred,
                statistics.median(t[0] for t in times["hpe hopenet"]),
                statistics.median(t[0] for t in times[every]),
                ref,
            )


def _exact_floor(gt: str, pred: str, hopenet_wall: float, every_wall: float, ref) -> None:
    """Print the floor of exact arithmetic for every protocol and the default run as a multiple of it."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import libm

    cc = libm.compiler()
    if cc is None:
        print("  exact-arithmetic floor: skipped (no C compiler for benchmarks/libm.py's shim)")
        return
    with tempfile.TemporaryDirectory(prefix="hpe_floor_") as tmp:
        costs = libm.scalar_costs(cc, Path(tmp))
        runs = (
            [libm.count_run(cc, Path(tmp), pred, gt, p) for p in ((), ("hopenet",))]
            if isinstance(costs, dict)
            else [costs]
        )
    bad = next((r for r in runs if isinstance(r, str)), None)
    if bad:
        print(f"  exact-arithmetic floor: skipped ({bad})")
        return
    extra = libm.libm_seconds(runs[0]["calls"], costs) - libm.libm_seconds(runs[1]["calls"], costs)
    floor = hopenet_wall + extra / libm.cores()
    versus = f", {floor / ref[0]:.2f}x DuckDB" if ref else ""
    print(
        f"  exact-arithmetic floor of every protocol: the hopenet run {hopenet_wall:.2f} s + the other protocols' "
        f"C library calls, {extra:.2f} s of CPU on {libm.cores()} cores = {floor:.2f} s{versus}; "
        f"hpe, every protocol: {every_wall:.2f} s, {every_wall / floor:.2f}x that floor"
    )


if __name__ == "__main__":
    main()
