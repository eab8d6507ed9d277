"""Units of a Panoptic relabelling and their part files: what a worker computes and writes (:func:`run_unit`),
the run's fingerprint that ``--resume`` checks (:func:`fingerprint`; the folder itself is :mod:`..parts`'s),
and ``--min-change`` (:class:`MinChange`, the one rule that crosses units, applied by the parent in order)."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pyarrow as pa

from ...errors import HpeError
from ...io import arrow_table
from ..parts import prepare_parts, stat_signature
from .plan import Config, process_chunk
from .stats import unit_stats


def reject_schema():
    """The schema of the rejects table (:data:`~.plan.REJECT_COLS`)."""

    return pa.schema(
        [
            ("sequence", pa.string()),
            ("frame", pa.int64()),
            ("person_id", pa.int64()),
            ("camera", pa.string()),
            ("reason", pa.string()),
            ("detail", pa.string()),
            ("fit_rmse", pa.float64()),
            ("n_pairs", pa.int64()),
            ("scale", pa.float64()),
        ]
    )


# ------------------------------------------------------------------- units
def make_units(plans: list) -> list:
    """Independent units of work: ``(sequence index, chunk index)`` in output order."""
    return [(si, ci) for si, p in enumerate(plans) for ci in range(len(p.chunks))]


def unit_task(plans: list, cfg: Config, unit: tuple, parts_dir) -> dict:
    """Everything a worker needs for one unit (small and picklable)."""
    si, ci = unit
    p = plans[si]
    return {
        "chunk": p.chunks[ci],
        "cameras": p.cameras,
        "sequence": p.sequence,
        "cfg": cfg,
        "skipped": p.skipped[ci] if ci < len(p.skipped) else None,
        "every": p.every,
        "stem": str(Path(parts_dir) / f"{si:04d}-{ci:06d}") if parts_dir is not None else None,
    }


def compute(task: dict) -> dict:
    """:func:`process_chunk` of one :func:`unit_task`."""
    return process_chunk(
        task["chunk"], task["cameras"], task["sequence"], task["cfg"], task.get("skipped"), task.get("every", 1)
    )


def run_unit(task: dict) -> dict:
    """Compute one unit and write its parts (labels and rejects as Arrow IPC
    files, then its counts as JSON, each by an atomic rename: a unit whose
    JSON exists is complete). Returns the counts; nothing big crosses processes."""

    res = compute(task)
    stem = task["stem"]
    write_part(f"{stem}.labels.arrow", arrow_table(res["table"]))
    write_part(f"{stem}.rejects.arrow", arrow_table(res["rejects"], reject_schema()))
    stats = unit_stats(res, task["cfg"])

    with open(f"{stem}.json.tmp", "w") as fh:
        json.dump(stats, fh)
    os.replace(f"{stem}.json.tmp", f"{stem}.json")
    return stats


def read_part(path):
    """A part file written by :func:`write_part` (memory-mapped)."""

    with pa.memory_map(str(path), "r") as src:
        return pa.ipc.open_file(src).read_all()


class MinChange:
    """``--min-change DEG``: keep a label only if its rotation differs by at least
    DEG degrees (geodesic) from the last label kept for the same (sequence,
    person, camera); labels arrive in frame order, whoever computed them."""

    def __init__(self, degrees: float):
        self.deg = float(degrees)
        self.last: dict = {}

    def apply(self, table, schema):

        n = table.num_rows
        if not n:
            return table, None
        R = np.stack([table.column(f"r{i}{j}").to_numpy() for i in range(3) for j in range(3)], 1)
        seq = table.column("sequence").to_pylist()
        pid = table.column("person_id").to_numpy()
        cam = table.column("camera").to_pylist()
        frame = table.column("frame").to_numpy()
        keep = np.ones(n, dtype=bool)
        angle = np.full(n, np.nan)
        since = np.full(n, -1, dtype=np.int64)
        last = self.last
        for k in range(n):  # sequential by nature: each decision depends on the previous kept label
            key = (seq[k], int(pid[k]), cam[k])
            prev = last.get(key)
            if prev is not None:
                # geodesic angle from the Frobenius distance: |R1 - R2|_F = 2 sqrt(2) sin(theta / 2)
                d = float(np.sqrt(np.sum((R[k] - prev[0]) ** 2)))
                a = 2.0 * np.degrees(np.arcsin(min(1.0, d / (2.0 * np.sqrt(2.0)))))
                if a < self.deg:
                    keep[k] = False
                    angle[k] = a
                    since[k] = prev[1]
                    continue
            last[key] = (R[k], int(frame[k]))
        if keep.all():
            return table, None
        drop = ~keep
        t_drop = table.filter(pa.array(drop))
        rej = {
            "sequence": t_drop.column("sequence"),
            "frame": t_drop.column("frame"),
            "person_id": t_drop.column("person_id"),
            "camera": t_drop.column("camera"),
            "reason": pa.array(["below --min-change"] * int(drop.sum()), pa.string()),
            "detail": pa.array([f"{a:.3g} deg since frame {f}" for a, f in zip(angle[drop], since[drop])], pa.string()),
            "fit_rmse": t_drop.column("fit_rmse"),
            "n_pairs": t_drop.column("n_pairs"),
            "scale": t_drop.column("scale"),
        }
        return table.filter(pa.array(keep)), pa.Table.from_pydict(rej).cast(schema)


def fingerprint(plans: list, cfg: Config, fmt: str) -> dict:
    """What a run's parts depend on: options, plans, and every input (:func:`input_signatures`)."""
    h = hashlib.sha256()
    for p in plans:
        h.update(f"{p.sequence}|{p.calibration}|{','.join(map(str, p.cameras.names))}|".encode())
        h.update(np.fromiter(p.frames, dtype=np.int64, count=len(p.frames)).tobytes())
        h.update(str([len(c) for c in p.chunks]).encode())
        h.update(f"every={p.every}:{[sorted(s) for s in p.skipped]}".encode())
    sysname = getattr(cfg.system, "name", cfg.system)
    return {
        "hpe_parts": 2,
        "format": fmt,
        "config": repr({**cfg.__dict__, "system": sysname, "min_change": None}),
        "plans": h.hexdigest(),
        "inputs": input_signatures(plans),
    }


#: how ``--resume`` tells that an input changed (stated in messages and in ``--help``)
HOW_COMPARED = (
    "calibration files by their contents (SHA-256), face files and hdFace3d.tar by size, modification time and inode"
)
#: what else differs when the plans do (the fingerprint's ``plans``)
DIFFER = "other sequences, cameras or frames"


def input_signatures(plans: list) -> dict:
    """path -> signature of every file the run reads: a calibration's SHA-256 of its contents, a face
    file's or tar's ``size:mtime_ns:inode`` (reading every face file again would cost as much as a unit)."""
    out = {}
    for p in plans:
        cal = str(p.calibration)
        try:
            out[cal] = "sha256:" + hashlib.sha256(Path(cal).read_bytes()).hexdigest()
        except OSError as exc:
            raise HpeError(f"{cal}: cannot read: {exc.strerror or exc}") from None
        files = {getattr(f, "path", f) for f in p.frames.values()}
        for s in p.skipped:
            files.update(getattr(f, "path", f) for f in s.values())
        for f in sorted(map(str, files)):
            out[f] = stat_signature(f)
    return out


def prepare_unit_parts(plans, cfg, fmt, output, resume: bool, overwrite: bool = False) -> Path:
    """The locked parts folder of this run (:func:`~hpe_cli.pipelines.parts.prepare_parts` with
    :func:`fingerprint`; release it with :func:`~hpe_cli.pipelines.parts.unlock_parts`)."""
    return prepare_parts(fingerprint(plans, cfg, fmt), output, resume, overwrite, compared=HOW_COMPARED, differ=DIFFER)


def check_done(tasks: list) -> None:
    """Before resuming: every unit marked done (its ``.json``) has readable parts, else name the part."""

    for t in tasks:
        stem = t["stem"]
        marker = Path(stem + ".json")
        if not marker.exists():
            continue
        fix = f"delete {Path(stem).name}.* in {Path(stem).parent} to compute that unit again, or run without --resume"
        try:
            json.loads(marker.read_text())
        except (OSError, ValueError) as exc:
            raise HpeError(f"{marker}: damaged part of the interrupted run ({_short(exc)}); {fix}") from None
        for suffix in (".labels.arrow", ".rejects.arrow"):
            part = Path(stem + suffix)
            if not part.exists():
                raise HpeError(f"{part}: missing part of the interrupted run (its unit is marked done); {fix}")
            try:
                with pa.memory_map(str(part), "r") as src:
                    pa.ipc.open_file(src)
            except (OSError, pa.ArrowException) as exc:
                raise HpeError(f"{part}: damaged part of the interrupted run ({_short(exc)}); {fix}") from None


def _short(exc) -> str:
    return " ".join(str(exc).split())[:120] or type(exc).__name__


def write_part(path, table) -> None:
    """An Arrow IPC part file, by an atomic rename (a part that exists is complete)."""

    tmp = f"{path}.tmp"
    with pa.OSFile(tmp, "wb") as sink, pa.ipc.new_file(sink, table.schema) as w:
        w.write_table(table)
    os.replace(tmp, path)
