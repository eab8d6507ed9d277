"""`hpe evaluate`'s key join beside the engines that could replace it (issue 33): time and peak RSS, same run.

    python benchmarks/evaluate_join.py [--rows 5000000] [--repeat 1] [--duckdb-memory 500MB]
        [--only read,duckdb,acero,numpy,hpe-ordered,hpe-shuffled] [--folder DIR]

The files are benchmarks/evaluate.py's (key ``image``, GT in 300w_lp, predictions in 6drepnet): one pair in GT
order and one with the predictions shuffled, written once to ``--folder`` (kept when given, so 30M pairs are
generated once).

The join's task is what hpe's readers hand it: both sides as Arrow batches (key, row, line, usable flag, the
three angles), every GT row paired with its prediction's row or -1 (missing), in GT order, streamed out in
batches; predictions without a GT row and duplicate keys on either side counted. Each candidate runs in a child
process (peak RSS is its VmHWM):

* read: the two sides read and turned into those batches, nothing joined (the candidates' common floor);
* duckdb: the batches copied into DuckDB tables (``memory_limit`` ``--duckdb-memory``, ``temp_directory`` for
  its spills), duplicates by ``GROUP BY``, the unmatched by an anti join, the pairs by ``LEFT JOIN ... ORDER BY``
  the GT row, fetched as Arrow batches;
* acero: pyarrow ``Table.join`` (left outer) then ``sort_by`` the GT row, both sides whole in memory;
* numpy: 64-bit key hashes (:func:`hpe_cli.io.key_hash.string_hashes`), ``argsort`` + ``searchsorted``, matches
  verified on the strings, both sides whole in memory;
* hpe-ordered / hpe-shuffled: the whole ``hpe evaluate --protocol hopenet`` on the ordered / shuffled files;
  the difference is what hpe's external join (``pipelines/evaluate/spill.py``) costs on top of streaming.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = pa.schema(
    [
        ("k", pa.string()),
        ("row", pa.int64()),
        ("line", pa.int64()),
        ("ok", pa.bool_()),
        ("a0", pa.float64()),
        ("a1", pa.float64()),
        ("a2", pa.float64()),
    ]
)


def side(path, batch_size=262_144):
    """One side as the join receives it from hpe's readers (key, row, line, usable, angles)."""
    row = 0
    for b in pq.ParquetFile(path).iter_batches(batch_size, columns=["image", "pitch", "yaw", "roll"]):
        n = b.num_rows
        cols = [b.column(0), pa.array(np.arange(row, row + n)), pa.array(np.arange(row + 2, row + n + 2))]
        cols += [pa.array(np.ones(n, bool)), b.column(1), b.column(2), b.column(3)]
        yield pa.RecordBatch.from_arrays(cols, schema=SCHEMA)
        row += n


def consume(batches) -> tuple:
    """``(GT rows, matched)`` of the paired batches (each batch's prediction angles touched)."""
    n = matched = 0
    for b in batches:
        pr = b.column("prow").to_numpy(zero_copy_only=False)
        matched += int((pr >= 0).sum())
        n += b.num_rows
        b.column("pa0").to_numpy(zero_copy_only=False)
    return n, matched


def join_duckdb(g, p, memory: str) -> tuple:
    import duckdb

    tmp = tempfile.mkdtemp(prefix="hpe_bench_duckdb_")
    try:
        con = duckdb.connect(config={"memory_limit": memory, "temp_directory": tmp})
        for name, path in (("g", g), ("p", p)):
            con.register("src", pa.RecordBatchReader.from_batches(SCHEMA, side(path)))
            con.execute(f"CREATE TABLE {name} AS SELECT * FROM src")
            con.unregister("src")
        dup = [
            con.sql(f"SELECT count(*) FROM (SELECT k FROM {t} GROUP BY k HAVING count(*) > 1)").fetchall() for t in "gp"
        ]
        unmatched = con.sql("SELECT count(*) FROM p ANTI JOIN g USING (k)").fetchall()
        rel = con.sql(
            "SELECT g.row, coalesce(p.row, -1) prow, p.line pline, p.ok pok, p.a0 pa0, p.a1 pa1, p.a2 pa2 "
            "FROM g LEFT JOIN p USING (k) ORDER BY g.row"
        )
        return (*consume(rel.to_arrow_reader(262_144)), dup, unmatched)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def join_acero(g, p) -> tuple:
    gt = pa.Table.from_batches(list(side(g)), SCHEMA)
    pt = pa.Table.from_batches(list(side(p)), SCHEMA).rename_columns(["k", "prow", "pline", "pok", "pa0", "pa1", "pa2"])
    j = gt.join(pt, "k", join_type="left outer").sort_by("row")
    return consume(j.to_batches(262_144))


def join_numpy(g, p) -> tuple:
    import pyarrow.compute as pc

    sys.path.insert(0, str(ROOT))
    from hpe_cli.io.key_hash import string_hashes

    def whole(path):
        t = pa.Table.from_batches(list(side(path)), SCHEMA)
        return t, np.concatenate([string_hashes(c, stems=False)[0] for c in t.column("k").chunks])

    gt, hg = whole(g)
    pt, hp = whole(p)
    order = np.argsort(hp)
    sp = hp[order]
    at = np.minimum(np.searchsorted(sp, hg), len(sp) - 1)
    hit = sp[at] == hg
    pidx = np.where(hit, order[at], -1)
    gi = np.flatnonzero(hit)
    assert pc.all(pc.equal(gt.column("k").take(gi), pt.column("k").take(pidx[gi]))).as_py()
    a0 = pt.column("a0").to_numpy()

    def batches():
        for a in range(0, len(hg), 262_144):
            pi = pidx[a : a + 262_144]
            yield pa.RecordBatch.from_arrays(
                [pa.array(pi), pa.array(np.where(pi >= 0, a0[np.maximum(pi, 0)], np.nan))], names=["prow", "pa0"]
            )

    return consume(batches())


def child(which: str, g, p, memory: str) -> None:
    if which == "read":
        out = (sum(b.num_rows for b in side(g)), sum(b.num_rows for b in side(p)))
    elif which == "duckdb":
        out = join_duckdb(g, p, memory)
    elif which == "acero":
        out = join_acero(g, p)
    else:
        out = join_numpy(g, p)
    hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM")][0].split()[1]
    print("RESULT", int(hwm) // 1024, out)


def run(cmd, env) -> tuple:
    """``(seconds, peak RSS MB)`` of one child (its VmHWM through /usr/bin/time's max RSS)."""
    t = time.perf_counter()
    r = subprocess.run(["/usr/bin/time", "-f", "MAXRSS %M", *cmd], capture_output=True, text=True, env=env)
    if r.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr[-2000:]}")
    rss = int(r.stderr.rsplit("MAXRSS", 1)[1].split()[0]) // 1024
    return time.perf_counter() - t, rss


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=5_000_000)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--duckdb-memory", default="500MB", help="DuckDB's memory_limit (it spills beyond it)")
    ap.add_argument("--only", default="read,duckdb,acero,numpy,hpe-ordered,hpe-shuffled")
    ap.add_argument("--folder", help="where the files are written once and kept (default: a temporary folder)")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(*args.child, args.duckdb_memory)
        return
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from evaluate import make_tables

    folder = Path(args.folder) if args.folder else Path(tempfile.mkdtemp(prefix="hpe_bench_join_"))
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    try:
        for name, shuffled in (("ordered", False), ("shuffled", True)):
            if not (folder / name / "pred.parquet").exists():
                (folder / name).mkdir(parents=True, exist_ok=True)
                make_tables(args.rows, folder / name, shuffled)
        s = folder / "shuffled"
        print(f"{args.rows:,} pairs, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start")
        for _ in range(args.repeat):
            for which in args.only.split(","):
                if which.startswith("hpe-"):
                    d = folder / which[4:]
                    cmd = [sys.executable, "-m", "hpe_cli", "evaluate", str(d / "pred.parquet"), str(d / "gt.parquet")]
                    cmd += ["--pred-system", "6drepnet", "--gt-system", "300w_lp", "--protocol", "hopenet"]
                    cmd += ["--json", str(d / "report.json"), "-q", "--overwrite"]
                else:
                    cmd = [sys.executable, __file__, "--duckdb-memory", args.duckdb_memory, "--child", which]
                    cmd += [str(s / "gt.parquet"), str(s / "pred.parquet")]
                sec, rss = run(cmd, env)
                print(f"  {which:<14} {sec:8.2f} s  peak RSS {rss:>6,} MB  (load {os.getloadavg()[0]:.1f})", flush=True)
    finally:
        if not args.folder:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
