"""``hpe biwi``: BIWI labels in the depth or RGB camera, with head boxes, a protocol subset and sequence splits."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..datasets.biwi import PROTOCOLS, protocol_mask, read_biwi_camera, sequence_split
from ..errors import HpeError
from ..io import check_output, system_metadata, write_table
from ..io.rejects import Rejects
from ..io.writers import AtomicFile
from ..rotation import get_system
from .pools import library_threads

#: the cameras BIWI labels can be expressed in
CAMERAS = ("depth", "rgb")


@dataclass(frozen=True)
class BiwiOptions:
    """The settings of ``hpe biwi`` (see its ``--help``; names as the options').

    ``system`` is a :class:`~hpe_cli.rotation.RotationSystem` or a name, resolved once; ``head_size`` the
    diameter (mm, 1-1000) of the sphere projected for the boxes; ``split`` two or three fractions >= 0 summing
    to 1 (or None); ``split_lists`` a folder for ``<split>_sequences.txt``; ``threads`` (>= 1, None: one per
    core, at most 8) the size of OpenCV's and pyarrow's thread pools for the run (the frames are read on one
    Python thread; the output is the same whatever the number).
    """

    camera: str = "depth"
    calibration: object = None
    head_size: float = 200.0
    system: object = "biwi"
    protocol: str = "all"
    split: tuple | None = None
    seed: int = 0
    split_lists: object = None
    rejects: object = None
    strict: bool = False
    overwrite: bool = False
    threads: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "system", get_system(self.system))
        t = self.threads
        if t is not None and (not isinstance(t, int) or isinstance(t, bool) or t < 1):
            raise ValueError(f"expected threads an integer >= 1 (or None: one per core), got {t!r}")
        # numbers as the command line gives them, so the metadata is the same bytes from the API
        object.__setattr__(self, "head_size", float(self.head_size))
        if self.camera not in CAMERAS:
            raise ValueError(f"expected camera {' or '.join(CAMERAS)}, got {self.camera!r}")
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"expected protocol {' or '.join(PROTOCOLS)}, got {self.protocol!r}")
        if not 1 <= self.head_size <= 1000:
            raise ValueError(f"expected head_size in 1..1000 mm, got {self.head_size!r}")
        if self.split is not None:
            fr = tuple(float(f) for f in self.split)
            if len(fr) not in (2, 3) or any(f < 0 for f in fr) or abs(sum(fr) - 1) > 1e-9:
                raise ValueError(f"expected two or three fractions >= 0 summing to 1, got {self.split!r}")
            object.__setattr__(self, "split", fr)


def run_biwi(input_path, output, opts: BiwiOptions) -> dict:
    """Read BIWI, write the label table (and the split's sequence lists); return a summary dict.

    A frame whose pose file is unreadable or invalid goes to ``opts.rejects``
    (``file, sequence, frame, reason``); without it, or with ``opts.strict``, any
    such frame is an error naming its file and nothing is written (the
    rejects rule, :func:`hpe_cli.io.rejects.rejects_rule`). With the default
    protocol, labels + rejects = the frames found. OpenCV's and pyarrow's pools are limited to
    ``opts.threads`` for the run (:func:`~hpe_cli.pipelines.pools.library_threads`).
    """
    with library_threads(opts.threads):
        return _run_biwi(input_path, output, opts)


def _run_biwi(input_path, output, opts: BiwiOptions) -> dict:
    """:func:`run_biwi` once the libraries' pools are limited."""
    check_output(output, opts.overwrite)
    rejects = Rejects(opts.rejects, opts.overwrite, strict=opts.strict)
    frame = _read_frames(input_path, opts, rejects)
    rejects.check()  # before anything is written
    keep = protocol_mask(frame, opts.protocol)
    frame = frame[keep].reset_index(drop=True)
    if frame.empty:
        raise HpeError(f"{input_path}: protocol {opts.protocol} keeps no frame")
    splits = None
    if opts.split is not None:
        splits = sequence_split(frame["sequence"], opts.split, opts.seed)
        where = {s: name for name, seqs in splits.items() for s in seqs}
        frame["split"] = [where[s] for s in frame["sequence"].astype(str)]
    if splits is not None and opts.split_lists is not None:
        for name in splits:  # refuse existing lists before writing anything
            check_output(Path(opts.split_lists) / f"{name}_sequences.txt", opts.overwrite)
    write_table(frame, output, opts.overwrite, _metadata(opts, splits))
    rejects.write()
    lists = _write_split_lists(splits, opts) if splits is not None and opts.split_lists is not None else []
    return {
        "rows": len(frame),
        "dropped": int((~keep).sum()),
        "sequences": int(frame["sequence"].nunique()),
        "splits": {k: len(v) for k, v in (splits or {}).items()},
        "lists": lists,
        "boxes": int(np.isfinite(frame["bbox_w"]).sum()),
        "rejected": len(rejects),
        "rejects_per_reason": dict(rejects.counts),
    }


def _read_frames(input_path, opts: BiwiOptions, rejects: Rejects):
    """The labels of every frame found, in ``opts.camera``; the frames that cannot be read go to ``rejects``."""
    bad: list = []
    frame = read_biwi_camera(
        input_path,
        camera=opts.camera,
        calibration=opts.calibration,
        head_size_mm=opts.head_size,
        system=opts.system,
        bad=bad,
    )
    if bad:
        rejects.first_where = bad[0]["message"]  # FILE: reason (each frame is its own file)
        rejects.add(
            {
                c: np.array([b[c] for b in bad], dtype=np.int64 if c == "frame" else object)
                for c in ("file", "sequence", "frame")
            },
            [b["reason"] for b in bad],
        )
    return frame


def _metadata(opts: BiwiOptions, splits) -> dict:
    """The table's metadata: the system's, and ``hpe:biwi`` (camera, head size, protocol, split)."""
    about = {
        "camera": opts.camera,
        "head_size_mm": opts.head_size,
        "protocol": opts.protocol,
        "split": None if splits is None else {"fractions": list(opts.split), "seed": opts.seed, "sequences": splits},
    }
    return {**system_metadata(opts.system), "hpe:biwi": json.dumps(about)}


def _write_split_lists(splits: dict, opts: BiwiOptions) -> list:
    """``<split>_sequences.txt`` (one sequence per line) in ``opts.split_lists``; returns their paths."""
    lists = []
    for name, seqs in splits.items():
        p = Path(opts.split_lists) / f"{name}_sequences.txt"
        with AtomicFile(p, opts.overwrite) as tmp:
            tmp.write_text("".join(f"{s}\n" for s in seqs), encoding="utf-8")
        lists.append(str(p))
    return lists


def summary_lines(s: dict, output, opts: BiwiOptions) -> list:
    """The summary of a :func:`run_biwi` result ``s``."""
    lines = [f"{s['rows']} frames of {s['sequences']} sequences ({opts.camera} camera, {opts.system.name}) -> {output}"]
    if s["dropped"]:
        lines.append(f"protocol {opts.protocol}: {s['dropped']} frames left out")
    if s["splits"]:
        lines.append(
            "split (sequences): "
            + ", ".join(f"{k} {v}" for k, v in s["splits"].items())
            + (f" -> {', '.join(s['lists'])}" if s["lists"] else "")
        )
    if s["rejected"]:
        lines.append(
            f"rejected {s['rejected']} frames: "
            + "; ".join(f"{v} {k}" for k, v in s["rejects_per_reason"].items())
            + f" -> {opts.rejects}"
        )
    return lines
