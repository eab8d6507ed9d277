"""The output transaction commits several files as a whole, also when the commit itself fails halfway
(the N-th placement fails: an injected error, a target name that became a folder, a read-only folder):
the files already placed are undone (new ones removed, replaced ones restored) and nothing staged is left."""

from __future__ import annotations

import errno
import os

import pytest

from conftest import hpe, hpe_popen, hpe_process
from hpe_cli.errors import HpeError
from hpe_cli.io import transaction as tx

from .conftest import temp_files, tree


def _stage(tmp_path, overwrite=False):
    """A run with a folder of 5 files (2 replace existing ones) and 2 single files (1 replaces)."""
    txn = tx.OutputTransaction()
    d = txn.stage_dir(tmp_path / "imgs", overwrite=overwrite)
    (d / "sub").mkdir()
    for k in range(4):
        (d / f"{k}.jpg").write_bytes(b"new%d" % k)
    (d / "sub" / "x.jpg").write_bytes(b"newx")
    for name in ("a.csv", "b.json"):
        tmp = txn.stage_file(tmp_path / name, overwrite=overwrite)
        tmp.write_bytes(b"new " + name.encode())
    return txn


def _existing(tmp_path):
    (tmp_path / "imgs").mkdir()
    (tmp_path / "imgs" / "1.jpg").write_bytes(b"old1")
    (tmp_path / "imgs" / "3.jpg").write_bytes(b"old3")
    (tmp_path / "a.csv").write_bytes(b"old a")
    os.chmod(tmp_path / "a.csv", 0o640)


@pytest.mark.parametrize("overwrite", [False, True])
@pytest.mark.parametrize("fail_at", range(7))
def test_nth_placement_fails(tmp_path, monkeypatch, fail_at, overwrite):
    if overwrite:
        _existing(tmp_path)
    before = tree(tmp_path)
    modes = {p: os.stat(tmp_path / p).st_mode for p in before if (tmp_path / p).is_file()}
    txn = _stage(tmp_path, overwrite)
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
    with pytest.raises(HpeError, match="permission denied") as err:
        txn.commit()
    assert str(calls[-1]) in str(err.value)
    assert tree(tmp_path) == before  # placed files undone, replaced ones restored
    assert {p: os.stat(tmp_path / p).st_mode for p in modes} == modes
    assert not temp_files(tmp_path)
    assert txn.state == "aborted"


def test_commit_without_failure_places_everything(tmp_path):
    _existing(tmp_path)
    _stage(tmp_path, overwrite=True).commit()
    assert (tmp_path / "imgs" / "1.jpg").read_bytes() == b"new1"
    assert (tmp_path / "imgs" / "sub" / "x.jpg").read_bytes() == b"newx"
    assert oct(os.stat(tmp_path / "a.csv").st_mode & 0o777) == oct(0o640)
    assert not temp_files(tmp_path)


def test_a_target_that_became_a_folder(tmp_path):
    """Another process makes a folder where a file goes, after the plan was checked: undone, named."""
    before = tree(tmp_path)
    txn = _stage(tmp_path)
    real = tx.place_file

    def place(src, dst, ow, undo, backups):
        if dst.name == "2.jpg":
            dst.mkdir()
        real(src, dst, ow, undo, backups)

    import unittest.mock

    with unittest.mock.patch.object(tx, "place_file", place), pytest.raises(HpeError, match="2.jpg"):
        txn.commit()
    assert tree(tmp_path) == {**before, "imgs": "dir", "imgs/2.jpg": "dir"}  # the other process's folder stays
    assert not temp_files(tmp_path)


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores folder permissions")
def test_a_read_only_subfolder_fails_halfway(tmp_path):
    """imgs/sub exists and is read-only: 0..3.jpg are placed first, then sub/x.jpg fails; all undone."""
    (tmp_path / "imgs" / "sub").mkdir(parents=True)
    before = tree(tmp_path)
    txn = _stage(tmp_path)
    os.chmod(tmp_path / "imgs" / "sub", 0o555)
    try:
        with pytest.raises(HpeError, match=r"sub/x.jpg: cannot write: permission denied"):
            txn.commit()
        assert tree(tmp_path) == before
        assert not temp_files(tmp_path)
    finally:
        os.chmod(tmp_path / "imgs" / "sub", 0o755)


def test_a_killed_runs_temps_are_removed_by_the_next_run(tmp_path):
    """Temps old and unlocked (their run is gone) are removed when a run stages into their folder; a live
    run's (locked) and young ones stay."""
    import fcntl
    import time

    old = time.time() - 2 * tx.SWEEP_AGE
    dead_file, dead_dir = tmp_path / ".hpe-deadbeef.tmp", tmp_path / ".hpe-0badcafe.tmp"
    live, young, other = tmp_path / ".hpe-12345678.tmp", tmp_path / ".hpe-87654321.tmp", tmp_path / ".hpe-x.tmp"
    dead_file.write_bytes(b"partial output")
    (dead_dir / "sub").mkdir(parents=True)
    (dead_dir / "sub" / "a.jpg").write_bytes(b"img")
    for p in (live, young, other):
        p.write_bytes(b"x")
    fd = os.open(live, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)  # a live run holds its temp
    try:
        for p in (dead_file, dead_dir, live, other):
            os.utime(p, (old, old))
        txn = tx.OutputTransaction()
        with txn.activate():
            txn.stage_file(tmp_path / "out.csv").write_text("a\n")
        names = sorted(os.listdir(tmp_path))
        assert names == sorted([live.name, young.name, other.name, "out.csv"]), names
    finally:
        os.close(fd)


def test_kill9_of_a_plain_run_then_another_run_cleans_up(tmp_path):
    """``hpe convert`` killed with SIGKILL mid-write leaves its temp; the next run in that folder removes it."""
    import signal as sg
    import subprocess
    import time

    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    src = tmp_path / "in.parquet"
    rng = np.random.default_rng(0)
    pq.write_table(pa.table({k: rng.uniform(-80, 80, 300_000) for k in ("pitch", "yaw", "roll")}), src)
    out = tmp_path / "out"
    out.mkdir()
    proc = hpe_popen(
        "convert",
        src,
        "-o",
        out / "a.csv",
        "--from",
        "300w_lp",
        "--to",
        "6drepnet",
        "--batch-size",
        "2000",
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    end = time.monotonic() + 60
    while time.monotonic() < end and proc.poll() is None and not temp_files(out):
        time.sleep(0.005)
    proc.send_signal(sg.SIGKILL)
    proc.wait()
    left = temp_files(out)
    assert left, "the run ended before it was killed"
    old = time.time() - 2 * tx.SWEEP_AGE
    for p in left:
        os.utime(p, (old, old))
    res = hpe_process("convert", src, "-o", out / "b.csv", "--from", "300w_lp", "--to", "6drepnet", "-q", text=False)
    assert res.returncode == 0, res.stderr
    assert sorted(os.listdir(out)) == ["b.csv"]


def test_a_target_folder_whose_sub_path_is_a_file(tmp_path):
    """imgs/sub is a file where the staged folder has sub/x.jpg: the files placed before are undone."""
    (tmp_path / "imgs").mkdir()
    (tmp_path / "imgs" / "sub").write_bytes(b"a file, not a folder")
    before = tree(tmp_path)
    txn = _stage(tmp_path)
    with pytest.raises(HpeError, match="sub"):
        txn.commit()
    assert tree(tmp_path) == before
    assert not temp_files(tmp_path)


def test_augment_out_images_commit_failing_halfway_leaves_nothing(tmp_path):
    """``hpe augment --out-images`` whose commit fails on a later image (its name is taken by a folder made
    after the run started) leaves none of the earlier images."""
    from .conftest import make_images

    imgs = tmp_path / "imgs"
    make_images(imgs, ["a.jpg", "b.jpg", "c.jpg"], size=(80, 60))
    t = tmp_path / "t.csv"
    t.write_text("image,pitch,yaw,roll\na.jpg,1,2,3\nb.jpg,4,5,6\nc.jpg,7,8,9\n")
    out = tmp_path / "ai"
    real = tx.place_file

    def place(src, dst, ow, undo, backups):
        if dst.name == "c.jpg":
            dst.mkdir()  # another process takes the name meanwhile
        real(src, dst, ow, undo, backups)

    import unittest.mock

    with unittest.mock.patch.object(tx, "place_file", place):
        res = hpe(
            "augment",
            t,
            "-o",
            tmp_path / "a.csv",
            "--image-size",
            "80",
            "60",
            "--hflip",
            "--images",
            imgs,
            "--out-images",
            out,
        )
    assert res.exit_code == 1 and "c.jpg" in res.output, res.output
    assert sorted(os.listdir(out)) == ["c.jpg"] and (out / "c.jpg").is_dir()  # only the other process's folder
    assert not (tmp_path / "a.csv").exists() and not temp_files(tmp_path)


@pytest.mark.parametrize("signal_at", range(7))
def test_a_signal_during_the_commit_is_held_until_it_is_complete(tmp_path, monkeypatch, signal_at):
    """A signal landing while the outputs are placed (after any placement, the last included, or while the commit
    is being recorded) waits for the commit: every output is in place and the run is reported complete, never
    'interrupted' with its outputs written (seen once under load: exit 143 with both outputs present)."""
    from hpe_cli.cli.signals import Interrupted

    tx.reset_run_state()
    late = []
    monkeypatch.setattr(tx, "_late_signal", late.append)
    txn = _stage(tmp_path)
    monkeypatch.setattr(tx, "_run", txn)  # the run's own transaction: its commit completes the run
    real, calls = tx.place_file, []

    def place(src, dst, ow, undo, backups):
        real(src, dst, ow, undo, backups)
        calls.append(dst)
        if len(calls) == signal_at + 1:  # what the handler does when the signal lands here
            exc = Interrupted(15)
            tx.request_stop(exc)
            assert tx.in_critical_section(exc)

    monkeypatch.setattr(tx, "place_file", place)
    txn.commit()
    assert txn.state == "committed" and tx.run_committed() and len(late) == 1
    assert (tmp_path / "a.csv").read_bytes() == b"new a.csv" and (tmp_path / "imgs" / "sub" / "x.jpg").exists()
    assert not temp_files(tmp_path)
    tx.reset_run_state()


def test_a_signal_held_by_a_failing_commit_is_raised_with_nothing_placed(tmp_path, monkeypatch):
    from hpe_cli.cli.signals import Interrupted

    tx.reset_run_state()
    monkeypatch.setattr(tx, "_late_signal", lambda exc: pytest.fail("the commit did not complete"))
    before = tree(tmp_path)
    txn = _stage(tmp_path)
    real, calls = tx.place_file, []

    def place(src, dst, ow, undo, backups):
        calls.append(dst)
        if len(calls) == 2:
            exc = Interrupted(15)
            assert tx.in_critical_section(exc)
        if len(calls) == 4:
            raise OSError(errno.EACCES, "Permission denied")
        real(src, dst, ow, undo, backups)

    monkeypatch.setattr(tx, "place_file", place)
    with pytest.raises(Interrupted):
        txn.commit()
    assert tree(tmp_path) == before and not temp_files(tmp_path)
    tx.reset_run_state()
