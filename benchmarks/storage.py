"""Throughput of the storage-kind kernels and of `hpe convert` on rotation vectors, next to SciPy and a Parquet copy.

    python benchmarks/storage.py [--rows 1000000]

Prints rows/s of hpe's rotvec/quaternion/6-D kernels and SciPy's equivalents, then `hpe convert`
img2pose (rx, ry, rz) -> 300w_lp end to end next to the floor (pyarrow read + write of the output's
width), and the peak RSS of the process.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from convert import best_of  # benchmarks/convert.py, beside this file
from scipy.spatial.transform import Rotation

from hpe_cli.pipelines.convert import ConvertOptions, run_convert
from hpe_cli.rotation import get_system
from hpe_cli.rotation import storage as st


def line(name, rows, seconds):
    print(f"  {name:<48} {rows / seconds / 1e6:8.2f} M rows/s  ({seconds * 1e3:8.1f} ms)")


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=int, default=1_000_000)
    n = ap.parse_args().rows
    rots = Rotation.random(n, random_state=0)
    R, rv, q = rots.as_matrix(), rots.as_rotvec(), rots.as_quat()
    print(f"kernels, {n:,} rows")
    line("hpe rotvec_to_matrix", n, best_of(lambda: st.rotvec_to_matrix(rv)))
    line("SciPy Rotation.from_rotvec().as_matrix()", n, best_of(lambda: Rotation.from_rotvec(rv).as_matrix()))
    line("hpe matrix_to_rotvec", n, best_of(lambda: st.matrix_to_rotvec(R)))
    line("SciPy Rotation.from_matrix().as_rotvec()", n, best_of(lambda: Rotation.from_matrix(R).as_rotvec()))
    line("hpe quaternion_to_matrix (xyzw)", n, best_of(lambda: st.quaternion_to_matrix(q, "xyzw")))
    line("SciPy Rotation.from_quat().as_matrix()", n, best_of(lambda: Rotation.from_quat(q).as_matrix()))
    line("hpe matrix_to_quaternion", n, best_of(lambda: st.matrix_to_quaternion(R, "xyzw")))
    line("SciPy Rotation.from_matrix().as_quat()", n, best_of(lambda: Rotation.from_matrix(R).as_quat()))
    d6 = st.matrix_to_sixd(R)
    line("hpe sixd_to_matrix (Gram-Schmidt)", n, best_of(lambda: st.sixd_to_matrix(d6)))

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "rv.parquet"
        pq.write_table(pa.table({"rx": rv[:, 0], "ry": rv[:, 1], "rz": rv[:, 2]}), src, compression="none")
        out = Path(tmp) / "out.parquet"
        t = best_of(
            lambda: run_convert(
                src, out, get_system("img2pose"), get_system("300w_lp"), ConvertOptions(overwrite=True)
            ),
            repeat=2,
        )
        width = pq.read_table(out)

        def floor():
            pq.read_table(src)
            pq.write_table(width, Path(tmp) / "floor.parquet", compression="none", use_dictionary=False)

        tf = best_of(floor, repeat=2)
        print(f"end to end, {n:,} rows, rotvec (img2pose) -> 300w_lp")
        line("hpe convert", n, t)
        line(f"floor: pyarrow read + write ({width.num_columns} float columns)", n, tf)
        print(f"  ratio {t / tf:.2f}x the floor")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
