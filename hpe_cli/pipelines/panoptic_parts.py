"""Units and their part files: what a worker computes and writes, what ``--resume`` keeps, and
``--min-change`` (the one rule that crosses units, applied by the parent in order)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError
from .panoptic_plan import Config, process_chunk
from .panoptic_stats import unit_stats


def _reject_schema():
    import pyarrow as pa

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
    import os

    from ..io import arrow_table

    res = compute(task)
    stem = task["stem"]
    _write_part(f"{stem}.labels.arrow", arrow_table(res["table"]))
    _write_part(f"{stem}.rejects.arrow", arrow_table(res["rejects"], _reject_schema()))
    stats = unit_stats(res, task["cfg"])
    import json

    with open(f"{stem}.json.tmp", "w") as fh:
        json.dump(stats, fh)
    os.replace(f"{stem}.json.tmp", f"{stem}.json")
    return stats


def _read_part(path):
    import pyarrow as pa

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
        import pyarrow as pa

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


def _fingerprint(plans: list, cfg: Config, fmt: str) -> dict:
    """What a run's parts depend on: options, plans, and every input (:func:`input_signatures`)."""
    import hashlib

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
    import hashlib

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


def stat_signature(path: str) -> str:
    """How ``--resume`` compares a large input (an image, a video, a face file): size, mtime and inode, or
    ``"missing"``."""
    import os

    try:
        st = os.stat(path)
    except OSError:
        return "missing"
    return f"stat:{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"


def parts_dir_for(output) -> Path:
    """Where a run's parts are kept until the commit (and for ``--resume``)."""
    out = Path(output)
    return out.parent / f".{out.name}.hpe-parts"


def _mismatch(d: Path, old: dict, fp: dict, compared: str = HOW_COMPARED, differ: str = DIFFER) -> str:
    """Why the parts in ``d`` (fingerprint ``old``) cannot be resumed by a run with fingerprint ``fp``."""
    again = "run without --resume to start over"
    if old.get("hpe_parts") != fp["hpe_parts"]:
        return f"{d}: its parts were made by another version of hpe; {again}"
    if old.get("config") != fp["config"] or old.get("format") != fp["format"]:
        return f"{d}: its parts were made with other inputs or options (here: other options); {again}"
    a, b = old.get("inputs", {}), fp["inputs"]
    for path in b:
        if path in a and a[path] != b[path]:
            how = (
                "its contents differ"
                if b[path].startswith("sha256:")
                else "it is gone"
                if b[path] == "missing"
                else "its size, modification time or inode differ"
            )
            n = sum(1 for q in b if q in a and a[q] != b[q])
            more = f" (and {n - 1} more inputs)" if n > 1 else ""
            return (
                f"{path}: changed since the interrupted run whose parts are in {d} ({how}){more}; "
                f"--resume compares {compared}; {again}"
            )
    return f"{d}: its parts were made with other inputs or options (here: {differ}); {again}"


def _remove_leftovers(d: Path) -> None:
    """Remove what the run that made ``d`` left half done: its staged outputs (``temps.json``: the
    ``.hpe-*.tmp`` files next to its outputs) and its unfinished part files (``*.tmp`` in ``d``)."""
    import json
    import os
    import re

    try:
        temps = json.loads((d / "temps.json").read_text())
    except (OSError, ValueError):
        temps = []
    for t in temps if isinstance(temps, list) else []:
        if isinstance(t, str) and re.fullmatch(r"\.hpe-[0-9a-f]{8}\.tmp", os.path.basename(t)):
            _rm(Path(t))
    for f in d.glob("*.tmp"):
        _rm(f)


def _rm(p: Path) -> None:
    import shutil

    try:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:
        raise HpeError(f"{p}: cannot remove a file of the interrupted run: {exc.strerror or exc}") from None


def record_temps(d: Path, temps) -> None:
    """Note the run's staged outputs in its parts folder, so the run that resumes (or replaces) it can remove
    them if this one never ends (``kill -9``, a power cut)."""
    import json
    import os

    tmp = d / "temps.json.tmp"
    tmp.write_text(json.dumps(sorted(map(os.fspath, temps))))
    os.replace(tmp, d / "temps.json")


#: parts folder -> file descriptor holding its lock (one run at a time per output)
_LOCKS: dict = {}


def _make(d: Path) -> bool:
    """Make the folder ``d`` (and its parents): True if this call made it, False if it was there."""
    try:
        d.mkdir(parents=True)
    except FileExistsError:
        return False
    return True


def lock_parts(d: Path, output) -> bool:
    """Create (if needed) and lock the parts folder ``d`` for this run, or fail at once with one line if
    another run holds it (two runs writing one output: one goes on, the other stops here, nothing mixed).
    Returns True when this run made the folder it locked (False: it was there, left by an earlier run).

    The lock is ``flock`` on the folder itself; a folder removed and made again by the other run meanwhile
    is detected (inode changed) and locked afresh."""
    import os

    try:
        import fcntl
    except ImportError:  # no flock on this platform: runs are not protected from each other
        return _make(d)
    held = _LOCKS.get(str(d))
    if held is not None:  # this process holds it already (the lock keeps other processes out)
        try:
            if os.stat(d).st_ino == os.fstat(held).st_ino:
                return False
        except FileNotFoundError:
            pass
        unlock_parts(d)
    for _ in range(100):
        made = _make(d)
        try:
            fd = os.open(d, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise HpeError(
                f"{output}: another hpe run is writing this output now (its parts are in {d}); "
                "wait for it to end, or choose another output"
            ) from None
        try:
            same = os.stat(d).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            _LOCKS[str(d)] = fd
            return made
        os.close(fd)
    raise HpeError(f"{d}: cannot lock the parts folder (it keeps being replaced by another run)")


def unlock_parts(d) -> None:
    """Release the lock taken by :func:`lock_parts` (after the folder is removed, or kept for --resume)."""
    import os

    fd = _LOCKS.pop(str(d), None)
    if fd is not None:
        os.close(fd)


def _prepare_parts(plans, cfg, fmt, output, resume: bool, overwrite: bool = False) -> Path:
    """The locked parts folder of this run (:func:`lock_parts`; release it with :func:`unlock_parts`)."""
    return prepare_parts(_fingerprint(plans, cfg, fmt), output, resume, overwrite)


def prepare_parts(fp: dict, output, resume: bool, overwrite: bool = False, **why) -> Path:
    """The locked parts folder of a run whose parts depend on ``fp`` (what :func:`_fingerprint` gives for
    relabel-panoptic; ``why``: ``compared`` and ``differ`` for the messages of :func:`_mismatch`)."""
    d = parts_dir_for(output)
    run_file = d / "run.json"
    # whether the folder was there is read when it is locked, not before: another run may end (and remove its
    # parts folder) between a look before the lock and the lock, and this run then makes a new one
    existed = not lock_parts(d, output)
    try:
        # with the lock no other run is writing this output: one that ended just now may have placed it
        if not overwrite and Path(output).exists():
            if not existed:
                import shutil

                shutil.rmtree(d, ignore_errors=True)
            raise HpeError(
                f"{output}: already exists (another run created it meanwhile; use --overwrite to replace it)"
            )
        _reuse_or_reset(d, run_file, fp, existed, resume, **why)
    except BaseException:
        unlock_parts(d)
        raise
    return d


def _reuse_or_reset(d: Path, run_file: Path, fp: dict, existed: bool, resume: bool, **why) -> None:
    """With the lock held: check the parts of an earlier run against ``fp`` (``resume``) or clear them."""
    import json
    import shutil

    if existed and not run_file.exists() and not any(d.iterdir()):
        existed = False  # made by a run that stopped before writing anything
    if existed:
        try:
            old = json.loads(run_file.read_text())
        except (OSError, ValueError):
            old = None
        if not isinstance(old, dict) or old.get("hpe_parts") not in (1, 2):
            raise HpeError(f"{d}: exists and is not an hpe parts folder; move it away")
        if resume and old != fp:
            raise HpeError(_mismatch(d, old, fp, **why))
        _remove_leftovers(d)
        if not resume:  # start afresh in the same (locked) folder
            for f in d.iterdir():
                shutil.rmtree(f) if f.is_dir() and not f.is_symlink() else f.unlink()
    if not run_file.exists():
        run_file.write_text(json.dumps(fp))


def check_done(tasks: list) -> None:
    """Before resuming: every unit marked done (its ``.json``) has readable parts, else name the part."""
    import json

    import pyarrow as pa

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


def _write_part(path, table) -> None:
    """An Arrow IPC part file, by an atomic rename (a part that exists is complete)."""
    import os

    import pyarrow as pa

    tmp = f"{path}.tmp"
    with pa.OSFile(tmp, "wb") as sink, pa.ipc.new_file(sink, table.schema) as w:
        w.write_table(table)
    os.replace(tmp, path)
