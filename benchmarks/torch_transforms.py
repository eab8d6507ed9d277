#!/usr/bin/env python3
"""Benchmark torchvision v2 pipelines with and without ``HeadPose``: the pose kernels' overhead.

A batch of 256 RGB uint8 images of 224x224 (one set of random parameters per call,
as v2 does for a batched tensor) with boxes, 68 keypoints per image and one
canonical pose per image goes through

    RandomHorizontalFlip (hpe's, re-indexing landmarks) -> RandomRotation(30)
    -> RandomResizedCrop(224, ratio=(1, 1)) -> ToDtype(float32, scale=True)

and the same pipeline without the poses (the floor: torchvision's own image,
box and keypoint kernels). It also times the pose kernels alone and the numpy
``augment_batch`` on the same batch. CPU always, CUDA too when present (timed
with ``torch.cuda.synchronize``). Prints the median of ``--repeat`` runs and
the peak RSS.

Usage::

    python benchmarks/torch_transforms.py
    python benchmarks/torch_transforms.py --batch 64 --repeat 5
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import torch  # noqa: E402
from torchvision import tv_tensors  # noqa: E402
from torchvision.transforms import v2  # noqa: E402

from hpe_cli.geometry.augment import augment_batch  # noqa: E402
from hpe_cli.torch import HeadPose, angles_to_canonical  # noqa: E402
from hpe_cli.torch import transforms as T  # noqa: E402


def _time(fn, repeat, device):
    """Median wall time; the RNG is reseeded per run so every pipeline draws the same random parameters."""
    times = []
    for k in range(repeat):
        torch.manual_seed(k)
        if device == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        fn()
        if device == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def run(device, batch, size, repeat):
    g = torch.Generator().manual_seed(0)
    images = tv_tensors.Image(torch.randint(0, 256, (batch, 3, size, size), dtype=torch.uint8, generator=g)).to(device)
    boxes = tv_tensors.BoundingBoxes(
        torch.tensor([[40.0, 40.0, 140.0, 150.0]]).repeat(batch, 1),
        format="XYWH",
        canvas_size=(size, size),
        device=device,
    )
    points = tv_tensors.KeyPoints(
        torch.rand(batch, 68, 2, generator=g) * (size - 1), canvas_size=(size, size), device=device
    )
    pyr = torch.empty(batch, 3).uniform_(-60, 60, generator=g).double()
    pose = HeadPose(angles_to_canonical(pyr, "300w_lp").float(), canvas_size=(size, size), device=device)
    steps = [
        T.RandomHorizontalFlip(p=1.0, scheme="ibug68"),
        v2.RandomRotation(30),
        v2.RandomResizedCrop(size, scale=(0.6, 1.0), ratio=(1.0, 1.0)),
        v2.ToDtype(torch.float32, scale=True),
    ]
    pipe = v2.Compose(steps)
    floor = _time(lambda: pipe(images, boxes, points), repeat, device)
    with_pose = _time(lambda: pipe(images, boxes, points, pose), repeat, device)
    # v2 needs an image, box or keypoints to size its random crop: one box stands in
    tiny = tv_tensors.BoundingBoxes(torch.zeros(1, 4), format="XYWH", canvas_size=(size, size), device=device)
    box_only = _time(lambda: pipe(tiny), repeat, device)
    pose_kernels = _time(lambda: pipe(tiny, pose), repeat, device) - box_only
    print(f"{device:4s}  {batch}x3x{size}x{size} uint8 + boxes + 68 keypoints")
    print(f"      v2 pipeline without poses (floor)   {floor * 1e3:9.2f} ms  ({batch / floor:8.0f} images/s)")
    print(
        f"      v2 pipeline with HeadPose           {with_pose * 1e3:9.2f} ms  "
        f"(overhead {100 * (with_pose - floor) / floor:+.1f} %)"
    )
    print(
        f"      the {batch} poses' kernels alone       {pose_kernels * 1e3:9.2f} ms  "
        f"(pipeline on 1 box + poses minus 1 box alone)"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--size", type=int, default=224)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    torch.set_num_threads(max(1, torch.get_num_threads()))
    print(f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads")
    run("cpu", args.batch, args.size, args.repeat)
    if torch.cuda.is_available():
        run("cuda", args.batch, args.size, args.repeat)
    else:
        print("cuda  not available: skipped")
    pyr = np.random.default_rng(0).uniform(-60, 60, (args.batch, 3))
    t = _time(
        lambda: augment_batch(pyr, op="rotate", angle=30.0, image_size=(args.size, args.size)), args.repeat, "cpu"
    )
    print(f"numpy augment_batch labels only ({args.batch} rows)   {t * 1e3:9.2f} ms")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
