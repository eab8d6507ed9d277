"""Export stage 3 in units: what runs on ``--workers`` processes or a Dask cluster, what ``--resume`` keeps.

The pixel tasks (:func:`.pixels.build_tasks`: one per source image, one per video) are cut into units, the
same cut whoever runs them: a video is read in blocks of :data:`BLOCK_FRAMES` frame numbers (each block one
seek, then decoded sequentially: :meth:`hpe_cli.datasets.panoptic_video.VideoFrames.read` with ``seek``), and
consecutive image tasks go together by :data:`UNIT_IMAGES`. Every order-dependent output (split, file names,
COCO ids, list order, shard boundaries) is decided by the parent before and after the units, from the rows'
order, so the bytes never depend on which worker ran what.

With a parts folder (``--scheduler`` or ``--resume``), unit ``k`` writes into ``.OUT.hpe-parts/``: its files
under ``<k>.files/`` (crops or frames, at their final relative paths), its crops for the pixel layouts in
``<k>.spill``, and last, by an atomic rename, ``<k>.json`` (each head's outcome): a unit is done iff its JSON
exists. The parent hard-links the files into the staging folder in unit order; the parts stay until the run
commits, so an interrupted run loses nothing.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from ...errors import HpeError
from ..parts import stat_signature
from . import workers

#: frame numbers per video unit (one seek per unit, then sequential decoding)
BLOCK_FRAMES = 256
#: image tasks (source images) per unit
UNIT_IMAGES = 64
#: how ``--resume`` tells that an input changed (stated in messages)
HOW_COMPARED = "label tables, the split file, images and videos by size, modification time and inode"
#: what a unit imports on its first run (local workers import it as they start)
WORKER_IMPORTS = ("cv2", "hpe_cli.io.jpeg", "hpe_cli.geometry.crop", "hpe_cli.datasets.panoptic_video")


def make_units(tasks: list) -> list:
    """Cut the tasks into units (lists of tasks), in task order; a video task becomes one task per block of
    :data:`BLOCK_FRAMES` frame numbers (``seek`` marked on all but the first block)."""
    units, images = [], []
    for t in tasks:
        if t[0] != "video":
            images.append(t)
            if len(images) >= UNIT_IMAGES:
                units.append(images)
                images = []
            continue
        if images:
            units.append(images)
            images = []
        blocks: dict = {}
        for fr in sorted(t[2]):
            blocks.setdefault(fr // BLOCK_FRAMES, {})[fr] = t[2][fr]
        for b in sorted(blocks):  # the first block decodes from frame 0; the others seek once
            units.append([["video", t[1], blocks[b], b > 0]])
    if images:
        units.append(images)
    return units


def unit_items(unit) -> int:
    """Heads in a unit (the progress bar's step)."""
    return sum(sum(map(len, t[2].values())) if t[0] == "video" else len(t[2]) for t in unit)


def unit_task(cfg: dict, unit: list, stem) -> dict:
    """What a worker needs for one unit (small and picklable); ``stem`` None: no parts (write into the stage)."""
    return {"cfg": cfg, "tasks": unit, "stem": None if stem is None else str(stem), "cwd": os.getcwd()}


def run_unit(task: dict):
    """Run one unit. Without a stem: returns ``(results, spill file or None)`` (files written into the stage).
    With a stem: writes the unit's parts (files, spill, then its JSON) and returns the number of heads."""

    cfg = dict(task["cfg"], made=set())
    stem = task["stem"]
    if stem is not None:
        cfg["root"] = stem + ".files"
        shutil.rmtree(cfg["root"], ignore_errors=True)  # what a killed run of this unit left
        spill = stem + ".spill"
    elif cfg["pixels"] != "file":
        fd, spill = tempfile.mkstemp(prefix=".spill-", suffix=".bin", dir=cfg["root"])
        os.close(fd)
    else:
        spill = None
    workers.init_worker(cfg)
    out: list = []
    fh = open(spill + (".tmp" if stem is not None else ""), "wb") if spill and cfg["pixels"] != "file" else None
    try:
        cfg["spill"] = fh
        for t in task["tasks"]:
            out += workers.work_items(t, task.get("cwd"))
    finally:
        cfg["spill"] = None
        if fh is not None:
            fh.close()
    if stem is None:
        return out, spill
    if fh is not None:
        os.replace(spill + ".tmp", spill)
    rows = [[int(i), str(r), int(w), int(h), _payload(p)] for i, r, w, h, p in out]
    with open(stem + ".json.tmp", "w") as f:
        json.dump({"results": rows, "spill": fh is not None}, f)
    os.replace(stem + ".json.tmp", stem + ".json")
    return len(rows)


def _payload(p):
    if p is None:
        return None
    if not (isinstance(p, tuple) and p and p[0] == "spill"):  # pragma: no cover - a unit always spills
        raise RuntimeError("export unit: pixels not in the spill file")
    _, off, n, shape = p
    return [int(off), int(n), None if shape is None else [int(v) for v in shape]]


def read_unit(stem: str):
    """A finished unit's ``(results, spill file or None, files folder)``, as :func:`run_unit` returns them."""

    d = json.loads(Path(stem + ".json").read_text())
    res = [
        (i, r, w, h, None if p is None else ("spill", p[0], p[1], None if p[2] is None else tuple(p[2])))
        for i, r, w, h, p in d["results"]
    ]
    return res, (stem + ".spill" if d["spill"] else None), stem + ".files"


def check_done(stems) -> None:
    """Before resuming: every unit marked done has readable parts, else name the part."""
    for stem in stems:
        marker = Path(stem + ".json")
        if not marker.exists():
            continue
        fix = f"delete {Path(stem).name}.* in {Path(stem).parent} to compute that unit again, or run without --resume"
        try:
            res, spill, _ = read_unit(stem)
        except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
            raise HpeError(f"{marker}: damaged part of the interrupted run ({_short(exc)}); {fix}") from None
        if spill is not None:
            need = max((p[1] + p[2] for *_, p in res if p is not None), default=0)
            try:
                size = os.path.getsize(spill)
            except OSError:
                raise HpeError(
                    f"{spill}: missing part of the interrupted run (its unit is marked done); {fix}"
                ) from None
            if size < need:
                raise HpeError(f"{spill}: damaged part of the interrupted run ({size} of {need} bytes); {fix}")


def _short(exc) -> str:
    return " ".join(str(exc).split())[:120] or type(exc).__name__


def link_files(src_dir: str, stage: Path, made: set) -> None:
    """Hard-link (else copy) every file of a unit's ``<k>.files/`` into the staging folder, same relative
    paths; the part stays (``--resume`` may need it again)."""

    for root, _dirs, files in os.walk(src_dir):
        rel = os.path.relpath(root, src_dir)
        dst_dir = stage if rel == "." else stage / rel
        if dst_dir not in made:
            dst_dir.mkdir(parents=True, exist_ok=True)
            made.add(dst_dir)
        for name in sorted(files):
            src, dst = os.path.join(root, name), dst_dir / name
            try:
                os.link(src, dst)
            except FileExistsError:
                raise HpeError(f"{dst}: written by two units of the export (two heads with one file name)") from None
            except OSError:
                shutil.copyfile(src, dst)


# ------------------------------------------------------------------------------------------ resume
def fingerprint(cfg: dict, units: list, opts, inputs) -> dict:
    """What a run's parts depend on: the pixel options, every unit's heads (crop boxes, sizes, file names,
    sources) and the inputs' signatures (:func:`input_signatures`)."""

    h = hashlib.sha256()
    for u in units:
        h.update(repr(u).encode())
        h.update(b"\n")
    pixel_cfg = {k: v for k, v in cfg.items() if k not in ("root", "made", "spill", "shown")}
    return {
        "hpe_parts": 2,
        "format": "export",
        "config": repr(sorted(pixel_cfg.items())),
        "plans": h.hexdigest(),
        "inputs": input_signatures(inputs, opts, units),
    }


def input_signatures(inputs, opts, units) -> dict:
    """path -> ``stat:size:mtime_ns:inode`` of every file the run reads: the label inputs (every file of a
    folder input), the split file, and every image and video the units read (``missing`` when absent)."""
    files = []
    for p in inputs:
        p = Path(p)
        if p.is_dir():
            files += sorted(str(q) for q in p.rglob("*") if q.is_file())
        else:
            files.append(str(p))
    if opts.split_file:
        files.append(str(opts.split_file))
    for u in units:
        for t in u:
            if t[0] in ("image", "video") and t[1] is not None:
                files.append(str(t[1]))
    out = {}
    for f in files:
        if f not in out:
            out[f] = stat_signature(f)
    return out
