"""Shared by ``benchmarks/convert.py`` and ``benchmarks/audit.py``: streaming floors, timed subprocesses, medians.

The floors are the ones docs/performance.md defines, streamed batch by batch as hpe reads: pyarrow reads the
input 65,536 rows at a time and (convert) writes a Parquet table of the output's width with the encoding hpe's
writer uses (floats plain, the rest snappy + dictionary), or (audit) only reads it. Each command and each floor
runs as its own process under GNU time (wall, user + system CPU, peak RSS); the rounds alternate hpe and floor
so both see the same load, and the medians of the rounds are printed with the ratio of medians.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
HPE = [sys.executable, "-c", 'from hpe_cli.cli.main import cli; cli(prog_name="hpe")']

FLOOR = r"""
import sys, numpy as np, pyarrow as pa, pyarrow.parquet as pq
inp, out, width = sys.argv[1], sys.argv[2], int(sys.argv[3])
rng = np.random.default_rng(0)
w = None
f = pq.ParquetFile(inp, pre_buffer=False, buffer_size=1 << 20)
for b in f.iter_batches(batch_size=65536):
    if width == 0:  # the read floor
        continue
    n = b.num_rows
    cols, names = list(b.columns), list(b.schema.names)
    while len(cols) < width - 1:
        cols.append(pa.array(rng.standard_normal(n))); names.append(f"x{len(cols)}")
    cols.append(pa.array(np.zeros(n, bool))); names.append("flag")
    b = pa.RecordBatch.from_arrays(cols, names=names)
    if w is None:
        floats = {x.name for x in b.schema if pa.types.is_floating(x.type)}
        w = pq.ParquetWriter(out, b.schema, use_dictionary=[c for c in names if c not in floats],
                             compression={c: ("none" if c in floats else "snappy") for c in names})
    w.write_batch(b)
if w is not None:
    w.close()
"""


def floor_cmd(inp, out, width: int) -> list:
    """The floor as a command: read ``inp`` batch by batch and write ``width`` columns to ``out`` (0: read only)."""
    return [sys.executable, "-c", FLOOR, str(inp), str(out), str(width)]


def timed(cmd) -> tuple:
    """``(wall s, cpu s, peak RSS MB)`` of one subprocess, from GNU time."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    res = subprocess.run(
        ["/usr/bin/time", "-f", "@@%e %U %S %M"] + [str(c) for c in cmd], env=env, text=True, capture_output=True
    )
    if res.returncode != 0:
        raise SystemExit(f"failed ({res.returncode}): {' '.join(map(str, cmd))}\n{res.stderr[-2000:]}")
    wall, user, system, kb = [ln for ln in res.stderr.splitlines() if ln.startswith("@@")][-1][2:].split()
    return float(wall), float(user) + float(system), int(kb) / 1024


def compare(name: str, hpe_cmd, floor, repeat: int = 3) -> dict:
    """Run hpe and its floor in alternating rounds; print and return the medians and ratios."""
    runs = {"hpe": [], "floor": []}
    for _ in range(repeat):
        runs["hpe"].append(timed(hpe_cmd))
        runs["floor"].append(timed(floor))
    med = {k: [statistics.median(r[i] for r in v) for i in range(3)] for k, v in runs.items()}
    (hw, hc, hm), (fw, fc, fm) = med["hpe"], med["floor"]
    print(
        f"  {name:<30} hpe {hw:6.2f} s (cpu {hc:6.2f} s, {hm:4.0f} MB)   floor {fw:6.2f} s (cpu {fc:6.2f} s, "
        f"{fm:4.0f} MB)   wall ratio {hw / fw:4.2f}  cpu ratio {hc / fc:4.2f}   load {os.getloadavg()[0]:.1f}",
        flush=True,
    )
    return {"hpe": med["hpe"], "floor": med["floor"], "wall_ratio": hw / fw, "cpu_ratio": hc / fc}


def make_angles(path: Path, n: int, seed: int = 0, matrix_path: Path | None = None) -> None:
    """``id, pitch, yaw, roll`` (300w_lp-like) in 1M-row pieces; ``matrix_path`` also gets ``id, r00..r22``."""
    from hpe_cli.rotation import get_system

    system = get_system("300w_lp")
    rng = np.random.default_rng(seed)
    wa = wm = None
    for lo in range(0, n, 1_000_000):
        m = min(1_000_000, n - lo)
        pyr = np.c_[rng.uniform(-89, 89, m), rng.uniform(-99, 99, m), rng.uniform(-89, 89, m)]
        ta = pa.table({"id": np.arange(lo, lo + m), "pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2]})
        wa = wa or pq.ParquetWriter(path, ta.schema)
        wa.write_table(ta)
        if matrix_path is not None:
            R = system.from_angles(pyr).reshape(m, 9)
            tm = pa.table({"id": ta["id"], **{f"r{k // 3}{k % 3}": np.ascontiguousarray(R[:, k]) for k in range(9)}})
            wm = wm or pq.ParquetWriter(matrix_path, tm.schema)
            wm.write_table(tm)
    wa.close()
    if wm is not None:
        wm.close()
