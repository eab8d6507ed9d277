"""The output transaction's commit of one staged folder of many new files (``hpe view``'s thumbnails,
``hpe augment --out-images``): placed whole (rename, :func:`hpe_cli.io.placement.rename_dir`) versus file by file
(the path for existing targets and small folders), beside the floor (one ``os.rename`` of a folder, no checks).

Run:  python benchmarks/commit_folder.py [--files 100000] [--size 5000]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path


def stage(root: Path, name: str, files: int, size: int):
    from hpe_cli.io import transaction as tx

    txn = tx.OutputTransaction()
    d = txn.stage_dir(root / name)
    (d / "thumbs").mkdir()
    blob = os.urandom(size)
    for k in range(files):
        (d / "thumbs" / f"{k:020x}.jpg").write_bytes(blob)
    return txn


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=100_000)
    ap.add_argument("--size", type=int, default=5000, help="bytes per file (a 128 px JPEG thumbnail: about 5 kB)")
    args = ap.parse_args(argv)
    from hpe_cli.io import transaction as tx

    out = {}
    with tempfile.TemporaryDirectory(prefix="hpe-commit-bench-") as tmp:
        root = Path(tmp)
        for label, threshold in (("file by file", 10**12), ("whole folder", tx.RENAME_MIN_FILES)):
            txn = stage(root, label.replace(" ", "_"), args.files, args.size)
            tx.RENAME_MIN_FILES = threshold
            t = time.perf_counter()
            txn.commit()
            out[label] = time.perf_counter() - t
            assert len(os.listdir(root / label.replace(" ", "_") / "thumbs")) == args.files
        d = root / "floor_src"
        (d / "thumbs").mkdir(parents=True)
        for k in range(args.files):
            (d / "thumbs" / f"{k:020x}.jpg").write_bytes(b"x")
        t = time.perf_counter()
        os.rename(d, root / "floor")
        floor = time.perf_counter() - t
    print(f"commit of one staged folder of {args.files:,} new files ({args.size} bytes each)")
    for label, dt in out.items():
        print(f"  {label:13s} {dt:8.3f} s")
    print(f"  floor (one os.rename, no checks) {floor:.4f} s; file by file / whole folder = "
          f"{out['file by file'] / out['whole folder']:.0f}x")  # fmt: skip


if __name__ == "__main__":
    main()
