#!/usr/bin/env python3
"""``HeadPoseDataset`` against a bare OpenCV loop doing the same work, in one process and in a DataLoader.

Both sides read the same AFLW2000-3D JPEGs (450x450) and, per sample,

    decode -> square crop (the label box + ``--margin`` on each side, zeros outside the image)
    -> resize to ``--size`` x ``--size`` (bilinear) -> horizontal flip

The bare loop is the floor: the least a loader can do to return what ``HeadPoseDataset``
returns for the image, and nothing more. It decodes with ``cv2.imread(f, cv2.IMREAD_COLOR_RGB)``
(the decoder writes RGB; with an OpenCV older than 4.10, ``IMREAD_COLOR`` and one
``cv2.cvtColor`` of the resized crop), crops with numpy slicing, ``cv2.resize``, ``cv2.flip``
and returns ``torch.from_numpy(hwc).permute(2, 0, 1)``: the same uint8 RGB pixels in the
same (3, H, W) channels-last tensor layout as the dataset (checked equal below), so a
DataLoader's collate does the same copy for both. (An earlier version returned BGR HWC numpy
arrays in one process, HWC tensors in the DataLoader: not the dataset's output, and a
different collate copy.) ``HeadPoseDataset`` decodes only the crop's rectangle of each JPEG when
``_hpe_jpeg`` is built (libjpeg-turbo: rows above it entropy-decoded only, columns beside it not
transformed, nothing below it), else whole frames with ``simplejpeg``; both give OpenCV's exact
pixels (:mod:`hpe_cli.io.jpeg`). A second floor row, "bare loop, same decoder", decodes the same
way with the same calls and nothing else, so the loader's own cost is printed too: the first row
is the floor the loader has to beat, the second shows what it costs over the decoder it uses.
``HeadPoseDataset`` also returns the pose (matrix, angles,
canonical, gimbal lock, undefined flag) after the flip, the box and the 68 landmarks
(moved and re-indexed) and the index. Three HeadPoseDataset configurations are timed:

- ``size=S, hflip=1``: crop, resize and flip in the decode step (OpenCV), the pose from
  the mirrored-pose table: the fast path, same pixels as the bare loop (checked);
- ``size=S`` + ``transform=T.RandomHorizontalFlip(p=1)`` (a 6DRepNet-style recipe: the dataset takes a
  leading hpe flip over into the decode step, so this runs as the fast path);
- ``transform=v2.Compose([v2.Resize((S, S)), T.RandomHorizontalFlip(p=1)])`` (torchvision's
  antialiased uint8 resize, a different filter from ``cv2.resize``).

Samples/s are the median of ``--repeat`` passes over ``--items`` items (the 16 (or 4
shipped) images cycled; the files stay in the page cache, so decode is CPU-bound), by
wall clock and by CPU time (this process + its finished workers: steadier on a shared
machine). The DataLoader runs use ``num_workers=2``, ``batch_size=16`` and the same items
for both sides (the bare loop wrapped in a minimal ``Dataset`` returning ``torch.from_numpy``).
Peak RSS is this process's (workers are separate processes) and the workers' largest.

Usage::

    python benchmarks/dataset.py
    python benchmarks/dataset.py --items 400 --repeat 3 --workers 2
    python benchmarks/dataset.py --fast-only --items 256 --repeat 7   # the floor and the fast path only
    python benchmarks/dataset.py --images /path/to/AFLW2000   # a folder of .mat + .jpg
    python benchmarks/dataset.py --panoptic   # the pizza1 HD frames (1920x1080), heads relabelled by hpe

``--panoptic`` labels the real CMU Panoptic sample (``hpe relabel-panoptic``, every labelled head in
the 8 HD frames shipped) and crops each head's box: a small part of a large frame, the case of
Panoptic, AGORA and BIWI training sets.
"""

from __future__ import annotations

import argparse
import math
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2
import numpy as np
import pandas as pd
import torch
from torchvision.transforms import v2

from hpe_cli import write_labels
from hpe_cli.datasets.mat import read_mat_dir
from hpe_cli.geometry.augment import box_of_points
from hpe_cli.torch import HeadPoseDataset
from hpe_cli.torch import transforms as T

REALDATA = ROOT.parent.parent / "shared" / "realdata" / "aflw2000_prnet"
for _cand in (Path("/work/shared/realdata/aflw2000_prnet"), REALDATA, ROOT / "sample_data" / "aflw2000"):
    if _cand.is_dir():
        DEFAULT_IMAGES = _cand
        break


def make_labels(folder: Path, out: Path) -> Path:
    """A Parquet label table of the folder's ``.mat`` files: pose, 68 landmarks (pt3d_68 x, y), their box."""
    table = read_mat_dir(folder, landmarks=True)
    p = "lm3d" if "lm3d0_x" in table.columns else "lm"  # 300W-LP samples may have pt2d only
    lm = np.stack([table[[f"{p}{i}_x", f"{p}{i}_y"]].to_numpy() for i in range(68)], axis=1)
    keep = ["file", "pitch", "yaw", "roll"]
    frame = table[keep].copy()
    frame["file"] = [str(folder / f).replace(".mat", ".jpg") for f in frame["file"]]
    extra = dict(zip(["bbox_x", "bbox_y", "bbox_w", "bbox_h"], box_of_points(lm)[0].T))
    extra.update({f"lm{i}_{a}": lm[:, i, k] for i in range(68) for k, a in enumerate("xy")})
    return write_labels(pd.concat([frame, pd.DataFrame(extra)], axis=1), out, system="300w_lp")


#: OpenCV >= 4.10 decodes straight into RGB, as ``HeadPoseDataset`` does
RGB = getattr(cv2, "IMREAD_COLOR_RGB", None)


PANOPTIC = ROOT.parent.parent / "shared" / "realdata" / "panoptic_160906_pizza1"
for _cand in (Path("/work/shared/realdata/panoptic_160906_pizza1"), PANOPTIC):
    if _cand.is_dir():
        PANOPTIC = _cand
        break


def make_panoptic_labels(seq: Path, out: Path) -> Path:
    """A Parquet label table of every head ``hpe relabel-panoptic`` labels in the HD frames shipped with ``seq``."""
    import subprocess

    raw = out.with_name("relabelled.parquet")
    subprocess.run(
        [sys.executable, "-m", "hpe_cli.cli.main", "relabel-panoptic", str(seq), "-o", str(raw), "--quiet"],
        check=True, cwd=ROOT, capture_output=True,
    )  # fmt: skip
    table = pd.read_parquet(raw)
    table["file"] = [
        str(seq / "hdImgs" / f"hd_{cam}" / f"{int(fr):08d}.jpg") for cam, fr in zip(table["camera"], table["frame"])
    ]
    table = table[[Path(f).is_file() for f in table["file"]]].reset_index(drop=True)
    keep = ["file", "pitch", "yaw", "roll", "bbox_x", "bbox_y", "bbox_w", "bbox_h"]
    keep += [c for c in table.columns if c.startswith("lm") and c.endswith(("_x", "_y"))]
    return write_labels(table[keep], out, system="300w_lp")


def square_crop(box, margin):
    """``(top, left, size)``: the same square as ``HeadPoseDataset(crop=margin, square=True)``."""
    x, y, w, h = box
    side = max(w, h) * (1.0 + 2.0 * margin)
    size = math.ceil(side)
    left, top = math.floor(x + w / 2.0 - size / 2.0), math.floor(y + h / 2.0 - size / 2.0)
    return top, left, size


class BareLoop(torch.utils.data.Dataset):
    """cv2.imread (RGB) -> square crop (zeros outside) -> cv2.resize -> cv2.flip -> (3, H, W) tensor: the floor."""

    def __init__(self, files, boxes, margin, size, decoder="cv2"):
        self.files, self.boxes, self.margin, self.size = list(files), np.asarray(boxes), margin, size
        self.decoder = decoder

    def __len__(self):
        return len(self.files)

    def sample(self, i):
        top, left, side = square_crop(self.boxes[i], self.margin)
        if self.decoder == "region":  # HeadPoseDataset's decoder: the crop's rectangle only (OpenCV's pixels)
            import _hpe_jpeg

            with open(self.files[i], "rb") as fh:
                got = _hpe_jpeg.decode_region(fh.read(), top, left, top + side, left + side, RGB is not None)
            band, rows, stride, H, W, y0, x0, dy, dx = got
            img = np.frombuffer(band, np.uint8).reshape(rows, stride // 3, 3)
            img, top, left = img[dy:, dx:], top - y0, left - x0  # the band from (y0, x0) on
            H, W = min(H - y0, img.shape[0]), min(W - x0, img.shape[1])
        elif self.decoder == "simplejpeg":  # HeadPoseDataset's decoder without _hpe_jpeg (whole frames)
            import simplejpeg

            with open(self.files[i], "rb") as fh:
                img = simplejpeg.decode_jpeg(fh.read(), colorspace="RGB" if RGB is not None else "BGR")
            H, W = img.shape[:2]
        else:
            img = cv2.imread(self.files[i], RGB if RGB is not None else cv2.IMREAD_COLOR)
            H, W = img.shape[:2]
        t0, l0, t1, l1 = max(top, 0), max(left, 0), min(top + side, H), min(left + side, W)
        if (t0, l0, t1, l1) == (top, left, top + side, left + side):
            crop = img[t0:t1, l0:l1]
        else:
            crop = np.zeros((side, side, 3), np.uint8)
            crop[t0 - top : t1 - top, l0 - left : l1 - left] = img[t0:t1, l0:l1]
        pix = cv2.flip(cv2.resize(crop, (self.size, self.size), interpolation=cv2.INTER_LINEAR), 1)
        if RGB is None:
            pix = cv2.cvtColor(pix, cv2.COLOR_BGR2RGB)
        return torch.from_numpy(pix).permute(2, 0, 1)

    __getitem__ = sample


def _cpu():
    own = time.process_time()
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own + kids.ru_utime + kids.ru_stime


def _rates(runs, items, repeat):
    """``{name: (samples/s by wall clock, by CPU time, ratio to the first run by wall clock, by CPU)}``.

    Rates are medians over ``repeat`` rounds. The runs are interleaved (one of each per
    round), so a load change on a shared machine hits them all alike, in an order reversed
    every other round (what runs second finds warmer caches: ~2% in one process). The ratio
    to the first run (the floor) is the median of the per-round ratios: each compares two
    runs a few hundred milliseconds apart, which cancels the slow drifts of a shared
    machine's speed (seen here: the same loop at 880 and at 1,220 samples/s minutes apart).
    """
    times = {name: [] for name in runs}
    for r in range(repeat):
        for name in list(runs)[:: -1 if r % 2 else 1]:
            fn = runs[name]
            t0, c0 = time.perf_counter(), _cpu()
            fn()
            times[name].append((time.perf_counter() - t0, _cpu() - c0))
    base = np.asarray(times[next(iter(runs))])
    return {
        name: tuple(items / np.median(t, axis=0)) + tuple(np.median(base / np.asarray(t), axis=0))
        for name, t in times.items()
    }


def one_process(get, order):
    def run():
        for k in order:
            get(k)

    return run


def through_loader(ds, order, workers, batch):
    def run():
        loader = torch.utils.data.DataLoader(
            ds, batch_size=batch, sampler=order, num_workers=workers, persistent_workers=False
        )
        for _ in loader:
            pass

    return run


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--images", type=Path, default=DEFAULT_IMAGES, help="folder of AFLW2000-3D .mat + .jpg")
    ap.add_argument("--panoptic", action="store_true", help=f"the Panoptic HD frames and heads of {PANOPTIC.name}")
    ap.add_argument("--items", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--size", type=int, default=224)
    ap.add_argument("--margin", type=float, default=0.25)
    ap.add_argument("--fast-only", action="store_true", help="time the bare loop and the fast path only")
    args = ap.parse_args(argv)
    imports = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # torch, torchvision, cv2 loaded
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as tmp:
        if args.panoptic:
            args.images = PANOPTIC
            labels = make_panoptic_labels(PANOPTIC, Path(tmp) / "labels.parquet")
        else:
            labels = make_labels(args.images, Path(tmp) / "labels.parquet")
        scheme = "face70" if args.panoptic else "ibug68"  # Panoptic's face has 70 landmarks
        flip = T.RandomHorizontalFlip(p=1.0, scheme=scheme)
        fused = HeadPoseDataset(labels, crop=args.margin, size=args.size, hflip=1.0, flip_scheme=scheme)
        v2flip = HeadPoseDataset(labels, crop=args.margin, size=args.size, transform=flip)
        v2ds = HeadPoseDataset(
            labels, crop=args.margin, transform=v2.Compose([v2.Resize((args.size, args.size)), flip])
        )
        bare = BareLoop(fused._image_refs, fused.boxes, args.margin, args.size)
        from hpe_cli.io.jpeg import fast_decoder, region_decoder

        fused[0]  # the process's first-image checks, before the decoder in use is read
        used = "region" if region_decoder() else "simplejpeg" if fast_decoder() == "simplejpeg" else None
        same_decoder = BareLoop(fused._image_refs, fused.boxes, args.margin, args.size, decoder=used)
        n = len(fused)
        order = [k % n for k in range(args.items)]
        # same pixels: the fused path's crop + resize + flip is the bare loop's, in RGB
        ref, got = bare[0], fused[0]["image"]
        same = ref.shape == got.shape and ref.stride() == got.stride() and torch.equal(ref, got)
        print(
            f"{n} images from {args.images}, {args.items} items, crop {args.margin:g} square, "
            f"resize {args.size}, hflip; median of {args.repeat}; torch threads 1, cv2 threads 1"
        )
        same = same and all(torch.equal(bare[k], same_decoder[k]) for k in range(n)) if used else same
        print(f"fast-path image tensor equal to the bare loop's (values, shape, strides): {same}")
        how = {"region": "the crop's rectangle of each JPEG (_hpe_jpeg, libjpeg-turbo)", "simplejpeg": "simplejpeg"}
        print(
            f"HeadPoseDataset decodes {how.get(used, 'with OpenCV')} (OpenCV's pixels, checked on this "
            "process's first image)" + ("; the second row is the bare loop with that decoder" if used else "")
        )
        sj_row = [("bare loop, same decoder", same_decoder, same_decoder.__getitem__)] if used else []
        configs = (
            ("bare cv2 loop", bare, bare.__getitem__),
            *sj_row,
            ("HeadPoseDataset(size, hflip)", fused, fused.__getitem__),
            ("HeadPoseDataset(size) + v2 flip", v2flip, v2flip.__getitem__),
            ("HeadPoseDataset + v2 Resize,flip", v2ds, v2ds.__getitem__),
        )[: 2 + len(sj_row) if args.fast_only else 4 + len(sj_row)]
        one = _rates({name: one_process(get, order) for name, _, get in configs}, args.items, args.repeat)
        dl = _rates(
            {name: through_loader(ds, order, args.workers, args.batch) for name, ds, _ in configs},
            args.items,
            args.repeat,
        )
        rows = [(name, one[name], dl[name]) for name, _, _ in configs]
        print(
            f"samples/s (x bare loop)  {'1 process: wall':>19s} {'CPU':>14s}   "
            f"{f'DataLoader({args.workers}): wall':>22s} {'CPU':>14s}"
        )
        for name, one, dl in rows:
            cells = [f"{v:7.0f} ({x:4.2f}x)" for v, x in zip(one[:2] + dl[:2], one[2:] + dl[2:])]
            print(f"{name:33s} {cells[0]:>15s} {cells[1]:>15s}   {cells[2]:>18s} {cells[3]:>15s}")
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"peak RSS: this process {own:.0f} MiB ({imports:.0f} MiB after the imports), largest worker {kids:.0f} MiB")


if __name__ == "__main__":
    main()
