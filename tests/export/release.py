"""A small synthetic multi-sequence CMU Panoptic release made from videos, and the exports the tests compare.

Two sequences x three HD cameras, frames 0..11, two people; the second sequence's videos end three frames
before its face files (``scripts/make_sample_data.py::make_video_release``). Each video frame k shows k as a
row of blocks (``encode_frame_number``), so a frame read from the wrong place is visible.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from conftest import hpe, sample_data_script

ROOT = Path(__file__).resolve().parents[2]
#: (id, layout options): every layout, 6drepnet in both forms
LAYOUTS = [
    ("whenet", ["--layout", "whenet"]),
    ("6drepnet", ["--layout", "6drepnet"]),
    ("6drepnet-crops", ["--layout", "6drepnet", "--form", "crops"]),
    ("directmhp", ["--layout", "directmhp", "--split", "camera:train=0.5,val=0.5"]),
    ("fsanet", ["--layout", "fsanet"]),
    ("hf", ["--layout", "hf"]),
]
LAYOUT_IDS = [k for k, _ in LAYOUTS]
OPTS = dict(LAYOUTS)


def make_release(dst: Path):
    """``dst/rel`` (the release) and ``dst/labels.parquet`` (its one-process relabel)."""
    root = sample_data_script().make_video_release(dst / "rel")
    labels = dst / "labels.parquet"
    res = hpe("relabel-panoptic", root, "-o", labels, "-q")
    assert res.exit_code == 0, res.output
    return root, labels


def export_args(layout_id, labels, root, out, rejects, *extra):
    return ["export", labels, "-o", out, *OPTS[layout_id], "--images", root, "--rejects", rejects, "-q", *extra]


def tree(folder: Path) -> dict:
    """relative path -> sha256 of every file (``dir`` for folders)."""
    out = {}
    for r, dirs, files in os.walk(folder):
        for name in dirs:
            out[os.path.relpath(os.path.join(r, name), folder)] = "dir"
        for name in files:
            p = os.path.join(r, name)
            out[os.path.relpath(p, folder)] = hashlib.sha256(Path(p).read_bytes()).hexdigest()
    return out
