"""``hpe export --resume`` after a signal (real subprocesses), for every layout, on the synthetic video release.

SIGTERM once the first units are done: one error line, exit 143, nothing in the output folder's place, no temp
file, the finished units kept; ``--resume`` then computes only the other units and writes the bytes of an
uninterrupted one-process run, leaving nothing behind. Also with ``--scheduler local`` (a LocalCluster), and a
worker killed with ``kill -9`` in the middle of a ``--workers 2`` run (one line; a resume finishes it).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from conftest import hpe, hpe_popen, repo_module

from .conftest import alive, children, temp_files

R = repo_module("tests/export/release.py")


@pytest.fixture(scope="module")
def release(tmp_path_factory):
    return R.make_release(tmp_path_factory.mktemp("release"))


def _wait_for_units(proc, parts: Path, n: int, seconds: float = 90):
    end = time.monotonic() + seconds
    while time.monotonic() < end and proc.poll() is None:
        if parts.is_dir() and len(list(parts.glob("[0-9]*.json"))) >= n:
            return True
        time.sleep(0.002)
    return False


def _interrupt_then_resume(release, tmp_path, lid, extra=(), sig=signal.SIGTERM):
    root, labels = release
    ref = tmp_path / "ref"
    res = hpe(*R.export_args(lid, labels, root, ref / "o", ref / "r.csv"))
    assert res.exit_code == 0, res.output
    dst = tmp_path / "dst"
    dst.mkdir()
    args = R.export_args(lid, labels, root, dst / "o", dst / "r.csv", "--resume", *extra)
    proc = hpe_popen(*args)
    parts = dst / ".o.hpe-parts"
    if not _wait_for_units(proc, parts, 1):
        out, err = proc.communicate()
        pytest.fail(f"the run ended before it could be interrupted: {err.decode()}")
    kids = children(proc.pid)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    lines = err.decode().strip().splitlines()
    if sig == signal.SIGKILL:  # no word from the run; its workers die with it, its temp files stay
        assert proc.returncode == -signal.SIGKILL
        end = time.monotonic() + 5
        while time.monotonic() < end and any(alive(k) for k in kids):
            time.sleep(0.05)
        assert not [k for k in kids if alive(k)], "workers outlived their parent (kill -9)"
    else:
        assert proc.returncode == 128 + sig, err.decode()
        assert lines == [f"Error: interrupted ({signal.Signals(sig).name})"], err.decode()
        assert temp_files(dst) == []
    done = len(list(parts.glob("[0-9]*.json")))
    assert done >= 1 and not (dst / "o").exists() and not (dst / "r.csv").exists()
    res = hpe(*args)
    assert res.exit_code == 0, res.output
    assert R.tree(dst / "o") == R.tree(ref / "o")
    assert (dst / "r.csv").read_bytes() == (ref / "r.csv").read_bytes()
    assert sorted(os.listdir(dst)) == ["o", "r.csv"]  # parts and temp files gone


@pytest.mark.parametrize("lid", R.LAYOUT_IDS)
def test_sigterm_then_resume_is_byte_identical(release, tmp_path, lid):
    _interrupt_then_resume(release, tmp_path, lid, ("--workers", "1"))


def test_kill9_then_resume_removes_the_leftovers(release, tmp_path):
    _interrupt_then_resume(release, tmp_path, "hf", ("--workers", "2"), sig=signal.SIGKILL)


def test_sigterm_of_a_local_cluster_run_then_resume(release, tmp_path):
    pytest.importorskip("distributed")
    _interrupt_then_resume(release, tmp_path, "whenet", ("--scheduler", "local", "--workers", "2"))


def test_a_killed_worker_is_one_line_and_the_run_resumes(release, tmp_path):
    root, labels = release
    ref = tmp_path / "ref"
    assert hpe(*R.export_args("hf", labels, root, ref / "o", ref / "r.csv")).exit_code == 0
    dst = tmp_path / "dst"
    dst.mkdir()
    args = R.export_args("hf", labels, root, dst / "o", dst / "r.csv", "--resume", "--workers", "2")
    proc = hpe_popen(*args)
    end = time.monotonic() + 60
    kids: set = set()
    while time.monotonic() < end and proc.poll() is None and len(kids) < 2:
        kids = children(proc.pid)
        time.sleep(0.01)
    if proc.poll() is not None or len(kids) < 2:
        proc.communicate()
        pytest.skip("the run ended before a worker could be killed")
    os.kill(sorted(kids)[0], signal.SIGKILL)
    _, err = proc.communicate(timeout=60)
    lines = err.decode().strip().splitlines()
    if proc.returncode == 0:  # the worker had no unit left to do
        pytest.skip("the killed worker was idle")
    assert proc.returncode == 1 and len(lines) == 1 and "worker process died" in lines[0], err.decode()
    assert not (dst / "o").exists() and temp_files(dst) == []
    res = hpe(*args)
    assert res.exit_code == 0, res.output
    assert R.tree(dst / "o") == R.tree(ref / "o")


def _cluster_workers(pid: int) -> set:
    """The LocalCluster's worker processes: the run's children started by multiprocessing's spawn (its nannies
    live in the run's own process), not its resource tracker."""
    out = set()
    for c in children(pid, recursive=False):
        try:
            with open(f"/proc/{c}/cmdline", "rb") as f:
                if b"spawn_main" in f.read():
                    out.add(c)
        except OSError:
            pass
    return out


def test_a_dask_worker_killed_mid_run(release, tmp_path):
    """Dask runs a lost worker's unit again (or the run ends with one line and resumes): the same bytes."""
    pytest.importorskip("distributed")
    root, labels = release
    ref = tmp_path / "ref"
    assert hpe(*R.export_args("hf", labels, root, ref / "o", ref / "r.csv")).exit_code == 0
    dst = tmp_path / "dst"
    dst.mkdir()
    args = R.export_args(
        "hf", labels, root, dst / "o", dst / "r.csv", "--resume", "--scheduler", "local", "--workers", "2"
    )
    proc = hpe_popen(*args)
    parts = dst / ".o.hpe-parts"
    end = time.monotonic() + 90
    workers: set = set()
    while time.monotonic() < end and proc.poll() is None:
        workers = _cluster_workers(proc.pid)
        if len(workers) >= 2 and parts.is_dir() and list(parts.glob("0*")):  # units under way
            break
        time.sleep(0.005)
    if proc.poll() is not None or len(workers) < 2:
        proc.communicate()
        pytest.skip("the run ended before a worker could be killed")
    os.kill(max(workers), signal.SIGKILL)
    _, err = proc.communicate(timeout=120)
    if proc.returncode != 0:
        lines = err.decode().strip().splitlines()
        assert proc.returncode == 1 and len(lines) == 1 and lines[0].startswith("Error:"), err.decode()
        res = hpe(*args)
        assert res.exit_code == 0, res.output
    assert R.tree(dst / "o") == R.tree(ref / "o")
    assert (dst / "r.csv").read_bytes() == (ref / "r.csv").read_bytes()
    assert sorted(os.listdir(dst)) == ["o", "r.csv"]
