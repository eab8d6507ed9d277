"""Timing of `hpe infer`'s search (run: python benchmarks/bench_infer.py).

Prints wall time per search next to a baseline in the same process: the same
576 candidates evaluated one RotationSystem at a time (the obvious loop).
"""

import sys
import time
from pathlib import Path

import numpy as np

from hpe_cli.rotation import frobenius
from hpe_cli.rotation import infer as inf

FIX = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "conventions"
sys.path.insert(0, str(FIX))
import lp300w  # noqa: E402
import sixdrepnet  # noqa: E402
import synergynet  # noqa: E402
import tddfa_v2  # noqa: E402


def timed(label, fn, repeat=5, rows=None):
    fn()  # warm caches
    t = time.perf_counter()
    for _ in range(repeat):
        fn()
    dt = (time.perf_counter() - t) / repeat
    extra = f"  {rows / dt:,.0f} rows/s" if rows else ""
    print(f"{label:<58} {dt * 1e3:9.1f} ms{extra}")
    return dt


def baseline_loop(pyr, M):
    systems = [c.system("x") for c in inf.candidates()]
    return np.array([frobenius(s.from_angles(pyr), M).max() for s in systems])


def main():
    P = ("pitch", "yaw", "roll")
    pyr = inf.spread_angles(64)
    M = lp300w.pose_matrix(*np.deg2rad(pyr).T)
    b = timed("baseline: 576 systems one by one, 64 samples", lambda: baseline_loop(pyr, M))
    v = timed(
        "batched candidate_matrices + errors, 64 samples",
        lambda: frobenius(inf.candidate_matrices(pyr), M[None]).max(1),
    )
    print(f"{'  speed-up':<58} {b / v:9.1f} x")
    timed(
        "infer_builder, vectorised callable (300W-LP builder)",
        lambda: inf.infer_builder(inf.as_builder(lp300w.pose_matrix, P), roles=P),
    )
    timed(
        "infer_builder, per-sample callable (6DRepNet get_R)",
        lambda: inf.infer_builder(inf.as_builder(sixdrepnet.get_R, P), roles=P),
    )
    yp = ("yaw", "pitch", "roll")
    timed(
        "infer_decoder, per-sample (3DDFA_V2 matrix2angle), 256 rotations",
        lambda: inf.infer_decoder(inf.as_decoder(tddfa_v2.matrix2angle, yp), roles=yp),
    )
    timed(
        "infer_decoder, no fit + probes (SynergyNet), 256 rotations",
        lambda: inf.infer_decoder(inf.as_decoder(synergynet.matrix2angle_corr, yp), roles=yp),
    )
    n = 200_000
    tp = np.random.default_rng(0).uniform(-180, 180, (n, 3))
    tR = inf.candidate_matrices(
        tp,
        inf.candidates().index(
            inf.candidate_of(__import__("hpe_cli.rotation", fromlist=["get_system"]).get_system("300w_lp"))
        ),
    )[0]
    timed(f"infer_table, {n:,} rows (search on 512, leaders on all)", lambda: inf.infer_table(tp, tR), 2, rows=n)


if __name__ == "__main__":
    main()
