#!/usr/bin/env python3
"""Benchmark ``hpe relabel-agora`` against a per-person loop in DirectMHP's style.

Replicates the synthetic fixture (``tests/data/agora/validation_0_withjv.pkl``,
3 images x 14 people, built by ``scripts/make_agora_fixture.py``) into one
large dataframe (default 1000 copies: 3000 images, 14000 people), pickles it
to a temporary folder, then in one process times:

1. the whole job, :func:`hpe_cli.pipelines.relabel.agora.write_outputs` (unpickle,
   flatten, vectorised fit/label/box/landmarks, Parquet), and its two parts;
2. a per-person loop written the way DirectMHP's ``auto_labels_generating``
   works: one similarity fit, one helmet projection, one box rule and one
   Euler decomposition per person, with numpy, on the already-flattened arrays
   (so it is compared with part 2 of the job only). It runs on the first
   ``--loop-people`` people and its rate is extrapolated.

Usage::

    python benchmarks/agora.py                  # 1000 copies (14000 people)
    python benchmarks/agora.py --copies 100 --loop-people 500
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "data" / "agora" / "validation_0_withjv.pkl"


def _umeyama(src, dst):
    """One face: dst ~= s R src + t (3 x P arrays)."""
    ms, md = src.mean(1, keepdims=True), dst.mean(1, keepdims=True)
    a, b = src - ms, dst - md
    U, D, Vt = np.linalg.svd(b @ a.T)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    s = np.trace(np.diag(D) @ S) / (a * a).sum()
    return R, md - s * R @ ms, s


def loop_relabel(people, n, sphere, ref, pairs, width, height):
    """DirectMHP-style loop over the first ``n`` people; returns how many get a label."""
    from hpe_cli.rotation import get_system

    f51, head = pairs
    E = np.diag([1.0, -1.0, -1.0])
    sys300 = get_system("300w_lp")
    labelled = 0
    for k in range(n):
        if not people.occlusion[k] < 90 or not people.valid[k]:
            continue
        dst = people.face3d[k][f51].T
        if not np.isfinite(dst).all():
            continue
        R, t, s = _umeyama(ref[:, head], dst)
        X = people.cam_R[k] @ (s * R @ sphere + t) + people.cam_t[k][:, None]
        if (X[2] <= 0).any():
            continue
        uv = (people.K[k] @ X)[:2] / X[2]
        x0, y0 = max(uv[0].min(), 0), max(uv[1].min(), 0)
        x1, y1 = min(uv[0].max(), width), min(uv[1].max(), height)
        w, h = x1 - x0, y1 - y0
        if not (w > 0 and h > 0 and h / w < 1.5 and w / h < 1.5 and w < 0.7 * width and h < 0.7 * height):
            continue
        A = E @ people.cam_R[k] @ R
        sys300.to_angles(A[None])
        labelled += 1
    return labelled


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--copies", type=int, default=1000)
    ap.add_argument("--loop-people", type=int, default=2000)
    a = ap.parse_args(argv)

    from hpe_cli.datasets.agora import read_agora
    from hpe_cli.geometry.helmet import helmet_points
    from hpe_cli.geometry.reference import agora_pairs, reference_head
    from hpe_cli.pipelines.relabel import agora as job
    from hpe_cli.pipelines.relabel.options import RelabelAgoraOptions

    base = pd.read_pickle(FIXTURE)
    big = pd.concat([base] * a.copies, ignore_index=True)
    big["imgPath"] = [f"{p[:-4]}_{k:06d}.png" for k, p in enumerate(big["imgPath"])]
    with tempfile.TemporaryDirectory() as tmp:
        pkl = Path(tmp) / "bench_withjv.pkl"
        big.to_pickle(pkl, protocol=4)
        opts = RelabelAgoraOptions(system="300w_lp")
        cfg = opts.config()

        t0 = time.perf_counter()
        stats = job.write_outputs([pkl], Path(tmp) / "out.parquet", opts)
        t_job = time.perf_counter() - t0

        t0 = time.perf_counter()
        people = read_agora(pkl)
        t_read = time.perf_counter() - t0
        t0 = time.perf_counter()
        job.relabel_people(people, cfg)
        t_vec = time.perf_counter() - t0

        n = min(a.loop_people, len(people))
        t0 = time.perf_counter()
        n_loop = loop_relabel(people, n, helmet_points(18).T, reference_head().T, agora_pairs(), 3840, 2160)
        t_loop = time.perf_counter() - t0

    N = len(people)
    print(f"dataframe: {len(big)} images, {N} people ({FIXTURE.name} x {a.copies})", file=sys.stderr)
    print(f"{'step':<44}{'people':>9}{'seconds':>10}{'people/s':>12}")
    print(f"{'hpe relabel-agora, whole job (Parquet out)':<44}{N:>9}{t_job:>10.2f}{N / t_job:>12.0f}")
    print(f"{'  read_agora (unpickle + flatten)':<44}{N:>9}{t_read:>10.2f}{N / t_read:>12.0f}")
    print(f"{'  relabel_people (vectorised)':<44}{N:>9}{t_vec:>10.2f}{N / t_vec:>12.0f}")
    print(f"{'per-person loop, DirectMHP style':<44}{n:>9}{t_loop:>10.2f}{n / t_loop:>12.0f}")
    print(
        f"speed-up of the labelling step: {(N / t_vec) / (n / t_loop):.1f}x  "
        f"(labelled: job {stats.labelled} of {N}; loop {n_loop} of its {n})"
    )


if __name__ == "__main__":
    main()
