"""Placing one output of a committing run (:mod:`hpe_cli.io.transaction`): files, whole new folders and
removals, each recording how to undo itself. Looked up through the transaction module at commit time (the fault
tests replace them there)."""

from __future__ import annotations

import errno
import os
import shutil
import stat
from pathlib import Path

from ..errors import HpeError
from .os_errors import TEMP_PREFIX


def temp_in(folder: Path) -> Path:
    """A fresh hpe temp path (``.hpe-*.tmp``) inside ``folder``, for staging and backups."""
    return folder / f"{TEMP_PREFIX}{os.urandom(4).hex()}.tmp"  # secrets.token_hex, without importing hashlib


def remove_path(p: Path) -> None:
    """Remove a file or a folder tree, quietly if it is gone already."""
    try:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink()
    except FileNotFoundError:
        pass
    except OSError:
        pass


def count_files(folder, stop: int) -> int:
    """Files under ``folder``, counted up to ``stop`` (a listing of 100,000 names is not read to the end)."""
    n, todo = 0, [os.fspath(folder)]
    while todo:
        with os.scandir(todo.pop()) as it:
            for e in it:
                if e.is_dir(follow_symlinks=False):
                    todo.append(e.path)
                else:
                    n += 1
                    if n >= stop:
                        return n
    return n


def rename_dir(s, make_parents, undo: list) -> bool:
    """Place staged folder ``s`` whole at its (new) target: True when placed, False to place its files instead."""
    target = s.target
    make_parents(target, target.parent)
    try:
        os.mkdir(target)  # claims the name: fails if a file or folder took it since the plan
    except OSError:
        return False
    try:
        os.rename(s.tmp, target)  # onto the empty folder just made: atomic, fails if something was put into it
    except OSError:
        try:
            os.rmdir(target)
        except OSError:
            pass
        return False
    undo.append(lambda: os.rename(target, s.tmp))
    return True


def unplace_file(path: Path, undo: list, backups: list) -> None:
    """Remove ``path`` undoably: renamed to a temp next to it (deleted once the commit is complete)."""
    bak = temp_in(path.parent)
    try:
        os.rename(path, bak)
    except FileNotFoundError:  # gone already
        return
    except OSError as exc:
        exc.hpe_target = path
        raise
    backups.append(bak)
    undo.append(lambda: os.rename(bak, path))


_NO_LINKS = {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK, errno.ENOSYS, errno.EXDEV}


def place_file(src: Path, dst: Path, overwrite: bool, undo: list, backups: list) -> None:
    """Move ``src`` to ``dst``: atomically create it, or replace it keeping its mode."""
    try:
        if overwrite and dst.exists():
            mode = stat.S_IMODE(os.stat(dst).st_mode)
            os.chmod(src, mode)
            bak = temp_in(dst.parent)
            try:
                os.link(dst, bak)
                backups.append(bak)
                undo.append(lambda: os.replace(bak, dst))
            except OSError:
                pass
            os.replace(src, dst)
            return
        try:
            os.link(src, dst)  # fails if dst exists, whoever created it
        except FileExistsError:
            raise HpeError(
                f"{dst}: already exists (another run created it meanwhile; use --overwrite to replace it)"
            ) from None
        except OSError as exc:
            if exc.errno not in _NO_LINKS:
                raise
            # no hard links here: claim the name atomically, then move the file onto it
            fd = os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            os.close(fd)
            undo.append(lambda: os.unlink(dst))
            os.replace(src, dst)
            return
        undo.append(lambda: os.unlink(dst))
        os.unlink(src)
    except FileExistsError:
        raise HpeError(
            f"{dst}: already exists (another run created it meanwhile; use --overwrite to replace it)"
        ) from None
    except OSError as exc:
        exc.hpe_target = dst
        raise
