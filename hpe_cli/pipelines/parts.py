"""Parts folders: where a job that runs in units keeps each unit's output until the run commits, and what
``--resume`` keeps of an interrupted run (shared by ``relabel-panoptic`` and ``export``).

A run's parts live in ``.OUT.hpe-parts/`` next to its output (:func:`parts_dir_for`), locked for the run
(:func:`lock_parts`), with the run's fingerprint in ``run.json`` (:func:`prepare_parts`): a run that resumes
must have the same fingerprint, and the message says which input changed (:func:`mismatch`). Large inputs
are compared by :func:`stat_signature`.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

from ..errors import HpeError


def stat_signature(path: str) -> str:
    """How ``--resume`` compares a large input (an image, a video, a face file): size, mtime and inode, or
    ``"missing"``."""
    try:
        st = os.stat(path)
    except OSError:
        return "missing"
    return f"stat:{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"


def parts_dir_for(output) -> Path:
    """Where a run's parts are kept until the commit (and for ``--resume``)."""
    out = Path(output)
    return out.parent / f".{out.name}.hpe-parts"


def mismatch(d: Path, old: dict, fp: dict, compared: str, differ: str) -> str:
    """Why the parts in ``d`` (fingerprint ``old``) cannot be resumed by a run with fingerprint ``fp``.

    ``compared`` says how the job compares its inputs (e.g. "images by size, modification time and inode"),
    ``differ`` what else differs when the fingerprint's other fields do ("other rows, boxes or images")."""
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


def remove_leftovers(d: Path) -> None:
    """Remove what the run that made ``d`` left half done: its staged outputs (``temps.json``: the
    ``.hpe-*.tmp`` files next to its outputs) and its unfinished part files (``*.tmp`` in ``d``)."""
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
    fd = _LOCKS.pop(str(d), None)
    if fd is not None:
        os.close(fd)


def prepare_parts(fp: dict, output, resume: bool, overwrite: bool = False, *, compared: str, differ: str) -> Path:
    """The locked parts folder of a run whose parts depend on ``fp`` (the job's fingerprint: ``hpe_parts``,
    ``format``, ``config``, ``inputs`` and what else it needs); ``compared`` and ``differ`` word the messages of
    :func:`mismatch`. Release the lock with :func:`unlock_parts`."""
    d = parts_dir_for(output)
    run_file = d / "run.json"
    # whether the folder was there is read when it is locked, not before: another run may end (and remove its
    # parts folder) between a look before the lock and the lock, and this run then makes a new one
    existed = not lock_parts(d, output)
    try:
        # with the lock no other run is writing this output: one that ended just now may have placed it
        if not overwrite and Path(output).exists():
            if not existed:
                shutil.rmtree(d, ignore_errors=True)
            raise HpeError(
                f"{output}: already exists (another run created it meanwhile; use --overwrite to replace it)"
            )
        _reuse_or_reset(d, run_file, fp, existed, resume, (compared, differ))
    except BaseException:
        unlock_parts(d)
        raise
    return d


def _reuse_or_reset(d: Path, run_file: Path, fp: dict, existed: bool, resume: bool, why: tuple) -> None:
    """With the lock held: check the parts of an earlier run against ``fp`` (``resume``) or clear them."""
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
            raise HpeError(mismatch(d, old, fp, *why))
        remove_leftovers(d)
        if not resume:  # start afresh in the same (locked) folder
            for f in d.iterdir():
                shutil.rmtree(f) if f.is_dir() and not f.is_symlink() else f.unlink()
    if not run_file.exists():
        run_file.write_text(json.dumps(fp))
