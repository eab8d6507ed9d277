"""Temps of runs that were killed: each run ``flock``s the temps it stages (the kernel drops the lock when
the process is gone, ``kill -9`` included); a later run staging into the same folder removes the temps that
are old and unlocked (:func:`sweep_stale_temps`), so a killed run does not leave its ``.hpe-*.tmp`` files for ever."""

from __future__ import annotations

import os
import re
import shutil
import stat
import time
from pathlib import Path

#: a temp of a run that is gone (killed) is removed by a later run staging into the same folder once it is
#: this old (seconds) and no process holds its lock
SWEEP_AGE = 60.0
_TEMP_NAME = re.compile(r"\.hpe-[0-9a-f]{8}\.tmp")


def lock_file(fd) -> None:
    """``flock`` the temp a run has just created: held while the run lives (also through ``kill -9``: the
    kernel drops it when the process is gone), so a later run can tell a dead run's temp from a live one's."""
    try:
        import fcntl

        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except (ImportError, OSError):
        pass


def sweep_stale_temps(folder: Path, own: set) -> None:
    """Remove the temps (``.hpe-<8 hex>.tmp``) in ``folder`` left by runs that were killed: older than
    :data:`SWEEP_AGE` and not locked by any live process. Best effort: anything unclear is left alone."""

    try:
        import fcntl
    except ImportError:
        return
    try:
        entries = [e for e in os.scandir(folder) if _TEMP_NAME.fullmatch(e.name)]
    except OSError:
        return
    now = time.time()
    for e in entries:
        path = Path(e.path)
        if path in own:
            continue
        try:
            st = os.lstat(path)
            if stat.S_ISLNK(st.st_mode) or now - st.st_mtime < SWEEP_AGE:
                continue
            fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0))
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # a live run holds it
            os.close(fd)
            continue
        try:
            if stat.S_ISDIR(st.st_mode):
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink()
        except OSError:
            pass
        finally:
            os.close(fd)
