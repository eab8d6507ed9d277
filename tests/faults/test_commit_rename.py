"""The commit's fast path: a staged folder whose target does not exist is renamed into place whole
(:func:`hpe_cli.io.transaction.rename_dir`). Same guarantees as file by file: all outputs or none (a later
placement failing renames it back), a name taken meanwhile or a file put into the claimed folder falls back to
the per-file path and its checks, the umask's modes, no temps left."""

from __future__ import annotations

import errno
import os
import stat

import pytest

from hpe_cli.errors import HpeError
from hpe_cli.io import transaction as tx

from .conftest import temp_files, tree

N = 300  # above RENAME_MIN_FILES


def _stage(tmp_path, n=N, overwrite=False):
    txn = tx.OutputTransaction()
    d = txn.stage_dir(tmp_path / "page" / "imgs", overwrite=overwrite)  # "page" does not exist either
    (d / "sub").mkdir()
    for k in range(n):
        (d / f"{k}.jpg").write_bytes(b"new%d" % k)
    (d / "sub" / "x.jpg").write_bytes(b"newx")
    for name in ("a.csv", "b.json"):
        tmp = txn.stage_file(tmp_path / name, overwrite=overwrite)
        tmp.write_bytes(b"new " + name.encode())
    return txn


def _spy_rename(monkeypatch):
    calls = []
    real = tx.rename_dir

    def spy(s, make_parents, undo):
        ok = real(s, make_parents, undo)
        calls.append(ok)
        return ok

    monkeypatch.setattr(tx, "rename_dir", spy)
    return calls


def test_a_new_folder_is_renamed_whole_with_the_umask_modes(tmp_path, monkeypatch):
    calls = _spy_rename(monkeypatch)
    placed = []
    real = tx.place_file
    monkeypatch.setattr(tx, "place_file", lambda src, dst, *a: (placed.append(dst), real(src, dst, *a)))
    _stage(tmp_path).commit()
    assert calls == [True] and sorted(p.name for p in placed) == ["a.csv", "b.json"]  # the folder: one rename
    out = tmp_path / "page" / "imgs"
    assert len(list(out.iterdir())) == N + 1 and (out / "7.jpg").read_bytes() == b"new7"
    assert (out / "sub" / "x.jpg").read_bytes() == b"newx"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o777 & ~umask  # as a plain mkdir
    assert stat.S_IMODE(os.stat(out / "sub").st_mode) == 0o777 & ~umask
    assert not temp_files(tmp_path)


def test_few_files_are_placed_one_by_one(tmp_path, monkeypatch):
    calls = _spy_rename(monkeypatch)
    _stage(tmp_path, n=3).commit()
    assert calls == [] and (tmp_path / "page" / "imgs" / "2.jpg").read_bytes() == b"new2"


@pytest.mark.parametrize("fail_at", range(2))
def test_a_later_placement_failing_renames_the_folder_back(tmp_path, monkeypatch, fail_at):
    before = tree(tmp_path)
    txn = _stage(tmp_path)
    calls = []
    real = tx.place_file

    def place(src, dst, ow, undo, backups):
        calls.append(dst)
        if len(calls) == fail_at + 1:
            exc = OSError(errno.EACCES, "Permission denied")
            exc.hpe_target = dst
            raise exc
        real(src, dst, ow, undo, backups)

    monkeypatch.setattr(tx, "place_file", place)
    with pytest.raises(HpeError, match="permission denied"):
        txn.commit()
    assert tree(tmp_path) == before and not temp_files(tmp_path) and txn.state == "aborted"


def test_the_name_taken_after_the_plan_falls_back_and_is_refused(tmp_path, monkeypatch):
    """Another process creates the folder with one of our names after the plan: the per-file path refuses
    that name, undoes everything, and leaves the other process's file alone."""
    txn = _stage(tmp_path)
    real = tx.rename_dir

    def racing(s, make_parents, undo):
        s.target.mkdir(parents=True)
        (s.target / "5.jpg").write_bytes(b"theirs")
        return real(s, make_parents, undo)

    monkeypatch.setattr(tx, "rename_dir", racing)
    with pytest.raises(HpeError, match=r"5\.jpg: already exists"):
        txn.commit()
    assert tree(tmp_path / "page") == {"imgs": "dir", "imgs/5.jpg": tree(tmp_path / "page")["imgs/5.jpg"]}
    assert (tmp_path / "page" / "imgs" / "5.jpg").read_bytes() == b"theirs"
    assert not (tmp_path / "a.csv").exists() and not temp_files(tmp_path)


def test_a_file_put_into_the_claimed_folder_falls_back(tmp_path, monkeypatch):
    """Between the claim (mkdir) and the rename another process puts a file in: the rename fails (the folder is
    not empty), the files are placed one by one beside theirs."""
    txn = _stage(tmp_path)
    real_rename = os.rename

    def rename(src, dst, *a, **k):
        if str(dst).endswith(os.sep + "imgs"):
            (tmp_path / "page" / "imgs" / "theirs.txt").write_bytes(b"theirs")
        return real_rename(src, dst, *a, **k)

    monkeypatch.setattr(tx.os, "rename", rename)
    txn.commit()
    out = tmp_path / "page" / "imgs"
    assert (out / "theirs.txt").read_bytes() == b"theirs" and len(list(out.iterdir())) == N + 2
    assert (out / "sub" / "x.jpg").read_bytes() == b"newx" and not temp_files(tmp_path)


def test_an_existing_target_is_merged_file_by_file(tmp_path, monkeypatch):
    calls = _spy_rename(monkeypatch)
    (tmp_path / "page" / "imgs").mkdir(parents=True)
    (tmp_path / "page" / "imgs" / "1.jpg").write_bytes(b"old1")
    with pytest.raises(HpeError, match=r"1\.jpg: already exists"):
        _stage(tmp_path).commit()
    assert calls == []
    _stage(tmp_path, overwrite=True).commit()
    assert (tmp_path / "page" / "imgs" / "1.jpg").read_bytes() == b"new1" and calls == []


def test_removals_are_part_of_the_commit_and_never_an_input(tmp_path, monkeypatch):
    """``remove_at_commit``: done after every placement, undone (renamed back) when a later step fails; an input
    of the run is refused."""
    (tmp_path / "old.jpg").write_bytes(b"old")
    (tmp_path / "in.csv").write_bytes(b"input")
    before = tree(tmp_path)
    txn = _stage(tmp_path, n=3)
    txn.add_input(tmp_path / "in.csv")
    with pytest.raises(HpeError, match="in.csv"):
        txn.remove_at_commit(tmp_path / "in.csv")
    txn.remove_at_commit(tmp_path / "old.jpg")
    txn.remove_at_commit(tmp_path / "gone.jpg")  # not there: nothing to do
    real = tx.unplace_file

    def unplace(path, undo, backups):
        real(path, undo, backups)
        if path.name == "gone.jpg":
            exc = OSError(errno.EIO, "I/O error")
            exc.hpe_target = path
            raise exc

    monkeypatch.setattr(tx, "unplace_file", unplace)
    with pytest.raises(HpeError, match=r"gone\.jpg: cannot write: input/output error"):
        txn.commit()
    assert tree(tmp_path) == before and not temp_files(tmp_path)  # old.jpg back, nothing placed
    txn = _stage(tmp_path, n=3)
    txn.remove_at_commit(tmp_path / "old.jpg")
    txn.commit()
    assert not (tmp_path / "old.jpg").exists() and (tmp_path / "page" / "imgs" / "2.jpg").exists()
    assert not temp_files(tmp_path)
