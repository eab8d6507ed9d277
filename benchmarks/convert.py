"""Throughput of the rotation kernels and of `hpe convert`, next to SciPy and a plain Parquet copy.

    python benchmarks/convert.py [--rows 1000000]

Targets (issue 2): matrix -> both solutions >= 5M rows/s; end to end <= 0.5x
SciPy's time and <= 1.5x the read+write floor of a table of the same width.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from scipy.spatial.transform import Rotation

from hpe_cli.io import LABEL_COLS
from hpe_cli.pipelines.convert import run_convert
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
    n = ap.parse_args().rows
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

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        inp = tmp / "in.parquet"
        pq.write_table(pa.table({"id": np.arange(n), "pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2]}), inp)

        # the floor: read the same input and write a table of the same width whose extra
        # columns hold ready-made values of the same kind (random floats and one bool)
        extra = {c: rng.standard_normal(n) for c in LABEL_COLS if c not in ("pitch", "yaw", "roll", "gimbal_lock")}
        extra["gimbal_lock"] = np.zeros(n, bool)

        def floor_table():
            t = pq.read_table(inp)
            for c, v in extra.items():
                t = t.append_column(c, pa.array(v))
            return t

        def floor_plain():  # pyarrow's defaults: snappy and dictionary pages everywhere
            pq.write_table(floor_table(), tmp / "floor.parquet")

        def floor():  # the encoding hpe's writer uses: floats plain, the rest snappy + dictionary
            t = floor_table()
            floats = {f.name for f in t.schema if pa.types.is_floating(f.type)}
            pq.write_table(
                t,
                tmp / "floor.parquet",
                use_dictionary=[n for n in t.schema.names if n not in floats],
                compression={n: ("none" if n in floats else "snappy") for n in t.schema.names},
            )

        def scipy_job():  # the same job written with SciPy: one solution, no lock flag
            t = pq.read_table(inp)
            a = np.c_[t["pitch"].to_numpy(), t["yaw"].to_numpy(), t["roll"].to_numpy()]
            A = Rotation.from_euler("xyz", -a, degrees=True).as_matrix()  # intrinsic X-Y-Z, left-handed
            T = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)
            Rs = T @ A @ T.T
            rot = Rotation.from_matrix(Rs)
            e1 = rot.as_euler("ZYX", degrees=True)
            back = Rotation.from_euler("ZYX", e1, degrees=True).as_matrix()
            err = np.linalg.norm((back - Rs).reshape(n, 9), axis=1)
            cols = {"id": t["id"], "yaw": e1[:, 0], "pitch": e1[:, 1], "roll": e1[:, 2]}
            cols.update({f"r{i}{j}": Rs[:, i, j] for i in range(3) for j in range(3)})
            cols["roundtrip_err"] = err
            pq.write_table(pa.table(cols), tmp / "scipy.parquet", compression="snappy")

        def hpe_job():
            run_convert(inp, tmp / "hpe.parquet", src, dst, overwrite=True)

        print(f"end to end (Parquet in -> Parquet out), {n:,} rows")
        t_plain = best_of(floor_plain)
        line("Parquet read + write, same width, defaults", n, t_plain)
        t_floor = best_of(floor)
        line("Parquet read + write, same width, hpe encoding", n, t_floor)
        t_scipy = best_of(scipy_job)
        line("SciPy job (one solution, no lock flag)", n, t_scipy)
        t_hpe = best_of(hpe_job)
        line("hpe convert 300w_lp -> scipy_zyx", n, t_hpe, t_scipy)
        print(
            f"  hpe / SciPy = {t_hpe / t_scipy:.2f} (target <= 0.5);  hpe / floor = {t_hpe / t_floor:.2f} "
            f"(target <= 1.5; {t_hpe / t_plain:.2f} against the defaults floor)"
        )


if __name__ == "__main__":
    main()
