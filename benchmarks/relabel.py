#!/usr/bin/env python3
"""Benchmark ``hpe relabel-panoptic`` against a per-face loop in WHENet's style.

Builds a synthetic Panoptic sequence (default 2,000 frames x 5 people x 31 HD
cameras, with ``scripts/make_sample_data.py``) in a temporary folder, then in
one process:

1. the vectorised job (:func:`hpe_cli.pipelines.relabel.panoptic.write_outputs`,
   streaming Parquet, 2-D landmarks included) over every frame;
2. a per-face loop written the way WHENet's ``prepare_images.py`` works
   (``sample_video`` -> ``save_img_head``): cameras outside, frames inside,
   the frame's JSON read on each call, and for each face one similarity fit
   (WHENet's column-by-column ``align``) and one projection call (helmet +
   landmarks, correct distortion), WHENet's label chain and its box rule. It
   runs on the first ``--loop-frames`` frames only (it is slow); its rate is
   per view, like the other.

Both rates are in faces x cameras (views) per second, read from the same
JSON files. Peak memory (``ru_maxrss``) is reported after each half and
after the whole sequence, to show that streaming keeps it flat as frames grow.

Usage::

    python benchmarks/relabel.py                 # 2000 frames x 5 people x 31 cameras
    python benchmarks/relabel.py --frames 200 --loop-frames 10
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from panoptic import sample_data_script  # benchmarks/panoptic.py, beside this file


# ---------------------------------------------------------- WHENet-style loop
def _align(model, data):
    """Horn/Umeyama as WHENet's ``align`` does it: one face, column by column."""
    mz = model - model.mean(1, keepdims=True)
    dz = data - data.mean(1, keepdims=True)
    W = np.zeros((3, 3))
    for col in range(model.shape[1]):
        W += np.outer(mz[:, col], dz[:, col])
    U, d, Vh = np.linalg.svd(W.T)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vh) < 0:
        S[2, 2] = -1
    rot = U @ S @ Vh
    rm = rot @ mz
    dots = sum(float(dz[:, c] @ rm[:, c]) for c in range(data.shape[1]))
    norms = sum(float(np.linalg.norm(mz[:, c]) ** 2) for c in range(model.shape[1]))
    s = dots / norms
    trans = data.mean(1, keepdims=True) - s * rot @ model.mean(1, keepdims=True)
    err = np.sqrt(((s * rot @ model + trans - data) ** 2).sum(0))
    return rot, trans, err, s


def _project(X, K, R, t, d):
    """One camera, 3 x N points, OpenCV's model (the fixed version of WHENet's)."""
    x = R @ X + t
    x = x[:2] / x[2]
    r = (x * x).sum(0)
    f = 1 + d[0] * r + d[1] * r * r + d[4] * r**3
    xd = x[0] * f + 2 * d[2] * x[0] * x[1] + d[3] * (r + 2 * x[0] ** 2)
    yd = x[1] * f + 2 * d[3] * x[0] * x[1] + d[2] * (r + 2 * x[1] ** 2)
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]])


def _inverse_rotate_zyx(M):
    """WHENet's decomposition (both solutions), one matrix."""
    if abs(M[0, 2]) > 0.9999999:
        x = np.arctan2(-M[1, 0], -M[2, 0]) if M[0, 2] > 0 else np.arctan2(M[1, 0], M[2, 0])
        y = -np.pi / 2 if M[0, 2] > 0 else np.pi / 2
        return np.array((x, y, 0.0)), np.array((x, y, 0.0))
    y0 = np.arcsin(-M[0, 2])
    y1 = np.pi - y0
    c0, c1 = np.cos(y0), np.cos(y1)
    return (
        np.array((np.arctan2(M[1, 2] / c0, M[2, 2] / c0), y0, np.arctan2(M[0, 1] / c0, M[0, 0] / c0))),
        np.array((np.arctan2(M[1, 2] / c1, M[2, 2] / c1), y1, np.arctan2(M[0, 1] / c1, M[0, 0] / c1))),
    )


def _select_euler(two):
    a, b = (list(v) for v in two)
    for v in (a, b):
        v[1] = v[1] - 360.0 if v[1] > 180.0 else v[1]
    for v in (a, b):
        if abs(v[2]) < 90 and abs(v[0]) < 90:
            return True, v
    return False, [-999, -999, -999]


def loop_relabel(seq_dir, frames: list, cams: list, sphere, ref, pairs):
    """The loop of WHENet's ``sample_video``/``save_img_head``, with the fixes of this tool.

    Cameras outside, frames inside; each call reads the frame's JSON (as
    ``save_img_head`` does), and each face gets one fit and one projection
    (helmet and landmarks together), the label chain and the box rule.
    Returns the rows it would write (dicts).
    """
    kp, kp_model = pairs
    E = np.diag([1.0, -1.0, -1.0])
    rows = []
    for cam in cams:
        K, R, t, d = cam["K"], cam["R"], cam["t"], cam["dist"]
        w, h = cam["width"], cam["height"]
        for frame in frames:
            with open(Path(seq_dir) / "hdFace3d" / f"faceRecon3D_hd{frame:08d}.json") as fh:
                people = json.load(fh)["people"]
            for person in people:
                face3d = np.asarray(person["face70"]["landmarks"]).reshape(-1, 3).T
                conf = np.asarray(person["face70"]["averageScore"])
                use = conf[kp] > 0.1
                if use.sum() < 7:
                    continue
                rot, trans, err, s = _align(ref[:, kp_model[use]], face3d[:, kp[use]])
                rmse = float(np.sqrt((err**2).mean()))
                if rmse > 2.0:
                    continue
                uv = _project(np.concatenate([s * rot @ sphere + trans, face3d], axis=1), K, R, t, d)
                helmet = uv[:, : sphere.shape[1]]
                x0, y0 = max(helmet[0].min(), 0), max(helmet[1].min(), 0)
                x1, y1 = min(helmet[0].max(), w), min(helmet[1].max(), h)
                ok, (pitch, yaw, roll) = _select_euler(np.rad2deg(_inverse_rotate_zyx(R @ rot @ E)))
                bw, bh = x1 - x0, y1 - y0
                if ok and bw > 0 and bh > 0 and max(bw / bh, bh / bw) <= 2:
                    A = E @ R @ rot
                    rows.append(
                        {
                            "frame": frame,
                            "camera": cam["name"],
                            "person_id": person["id"],
                            "bbox": (x0, y0, bw, bh),
                            "pyr": (pitch, -yaw, -roll),
                            "A": A,
                            "rmse": rmse,
                            "lm": uv[:, sphere.shape[1] :].T,
                        }
                    )
    return rows


# -------------------------------------------------------------------- main
def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument("--people", type=int, default=5)
    ap.add_argument("--cameras", type=int, default=31)
    ap.add_argument("--loop-frames", type=int, default=40, help="frames given to the slow loop")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--keep", help="build the sequence here (kept) instead of a temporary folder")
    a = ap.parse_args(argv)

    from hpe_cli.geometry.helmet import helmet_points
    from hpe_cli.geometry.reference import panoptic_pairs, reference_head
    from hpe_cli.pipelines.relabel import panoptic as job
    from hpe_cli.pipelines.relabel import plan as planning
    from hpe_cli.pipelines.relabel.options import RelabelPanopticOptions

    gen = sample_data_script()
    with tempfile.TemporaryDirectory() as tmp:
        seq = Path(a.keep) if a.keep else Path(tmp) / "bench_seq"
        if not (seq / "hdFace3d").is_dir():
            t0 = time.perf_counter()
            gen.make_synthetic(seq, a.frames, a.people, a.cameras, special=False)
            print(
                f"built {seq}: {a.frames} frames x {a.people} people x {a.cameras} cameras "
                f"in {time.perf_counter() - t0:.1f} s",
                file=sys.stderr,
            )
        p = planning.plan(seq)
        views = len(p.frames) * a.people * len(p.cameras)
        opts = RelabelPanopticOptions(system="300w_lp", preset="whenet", workers=a.workers)

        # 1. vectorised, streamed; memory after half and after all of the sequence
        half = planning.plan(seq, frames=(None, min(p.frames) + len(p.frames) // 2))
        job.write_outputs(half, Path(tmp) / "half.parquet", opts)
        rss_half = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        t0, c0 = time.perf_counter(), time.process_time()
        stats = job.write_outputs(p, Path(tmp) / "all.parquet", opts)
        t_vec, c_vec = time.perf_counter() - t0, time.process_time() - c0
        rss_all = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

        # 2. the loop, on the first frames
        c = p.cameras
        cams = [
            {
                "name": c.names[i],
                "K": c.K[i],
                "R": c.R[i],
                "t": c.t[i][:, None],
                "dist": c.dist[i],
                "width": c.width[i],
                "height": c.height[i],
            }
            for i in range(len(c))
        ]
        sphere = helmet_points(22).T
        loop_frames = list(p.frames)[: a.loop_frames]
        t0, c0 = time.perf_counter(), time.process_time()
        n_loop = len(loop_relabel(seq, loop_frames, cams, sphere, reference_head().T, panoptic_pairs()))
        t_loop, c_loop = time.perf_counter() - t0, time.process_time() - c0
        loop_views = len(loop_frames) * a.people * len(p.cameras)

    rate_vec, rate_loop = views / t_vec, loop_views / t_loop
    cpu_vec, cpu_loop = views / c_vec, loop_views / c_loop
    print(
        f"sequence: {len(p.frames)} frames x {a.people} people x {len(p.cameras)} cameras = {views} views"
        f" (workers: {a.workers})"
    )
    print(f"{'method':<36}{'views':>9}{'wall s':>9}{'views/s':>10}{'CPU s':>9}{'views/CPU-s':>13}")
    print(
        f"{'hpe relabel-panoptic (vectorised)':<36}{views:>9}{t_vec:>9.2f}{rate_vec:>10.0f}{c_vec:>9.2f}"
        f"{cpu_vec:>13.0f}"
    )
    print(
        f"{'per-face loop, WHENet style':<36}{loop_views:>9}{t_loop:>9.2f}{rate_loop:>10.0f}{c_loop:>9.2f}"
        f"{cpu_loop:>13.0f}"
    )
    per_cpu = (
        f", {cpu_vec / cpu_loop:.1f}x per CPU-second"
        if a.workers == 1
        else " (with --workers > 1 the CPU columns and the peak RSS leave out the worker processes)"
    )
    print(
        f"speed-up: {rate_vec / rate_loop:.1f}x wall-clock{per_cpu}; labelled: vectorised {stats.labelled} "
        f"of {views}, loop {n_loop} of {loop_views}"
    )
    print(f"peak RSS: {rss_half:.0f} MB after {len(half.frames)} frames, {rss_all:.0f} MB after {len(p.frames)} frames")


if __name__ == "__main__":
    main()
