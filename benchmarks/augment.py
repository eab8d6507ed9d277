"""Throughput of the augmentation library: the vectorised batch form vs a per-row loop.

Run:  python benchmarks/augment.py [--rows 1000000] [--loop-rows 20000] [--chunk 100000]

Prints rows/s for
- labels only (pitch, yaw, roll -> both solutions + matrix), all rows in one call;
- labels + 68 landmarks + box, in chunks of ``--chunk`` rows (68 landmarks of 1M rows
  are 1.1 GB per copy, so the batch form is fed in chunks, as a data loader would);
- the same through :func:`augment_sample` one row at a time, on ``--loop-rows`` rows
  (the baseline; a full 1M-row loop would take minutes).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hpe_cli.geometry.augment import augment_batch, augment_sample


def _data(n, rng):
    pyr = rng.uniform(-180, 180, (n, 3))
    pyr[:, 1] = rng.uniform(-90, 90, n)
    lm = rng.uniform(0, 450, (n, 68, 2))
    box = np.c_[rng.uniform(0, 300, (n, 2)), rng.uniform(20, 150, (n, 2))]
    return pyr, lm, box


def _rate(n, seconds):
    return f"{n / seconds:>12,.0f} rows/s  ({n:,} rows in {seconds:.2f} s)"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--loop-rows", type=int, default=20_000)
    ap.add_argument("--chunk", type=int, default=100_000)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    n = args.rows
    pyr = rng.uniform(-180, 180, (n, 3))
    angles = rng.uniform(-30, 30, n)

    print(f"hpe augment library, {n:,} rows")
    for op, ang in (("hflip", None), ("rotate", angles), ("mirror", angles)):
        t = time.perf_counter()
        augment_batch(pyr, op=op, angle=ang, image_size=(450, 450))
        print(
            f"  batch, labels only, {op:<7}{' (per-row angles)' if ang is not None else '                 '}"
            f"{_rate(n, time.perf_counter() - t)}"
        )

    for op in ("hflip", "rotate"):
        spent = 0.0
        done = 0
        while done < n:
            m = min(args.chunk, n - done)
            p, lm, box = _data(m, rng)  # not timed
            t = time.perf_counter()
            augment_batch(
                p, lm, box, op=op, angle=angles[done : done + m] if op == "rotate" else None, image_size=(450, 450)
            )
            spent += time.perf_counter() - t
            done += m
        print(f"  batch, labels+68 lm+box, {op:<7} (chunks of {args.chunk:,})   {_rate(n, spent)}")

    k = args.loop_rows
    p, lm, box = _data(k, rng)
    for op in ("hflip", "rotate"):
        t = time.perf_counter()
        for i in range(k):
            augment_sample(
                p[i], lm[i], box[i], op=op, angle=float(angles[i]) if op == "rotate" else None, image_size=(450, 450)
            )
        dt = time.perf_counter() - t
        print(
            f"  per-row loop (baseline), labels+68 lm+box, {op:<7}  {_rate(k, dt)}"
            f"  -> {n:,} rows would take {n * dt / k:.0f} s"
        )


if __name__ == "__main__":
    main()
