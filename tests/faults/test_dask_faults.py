"""Dask under faults: ``--scheduler`` addresses that refuse, or accept and never answer, fail in seconds with
one line (no Dask import needed for that); SIGTERM during a LocalCluster run ends with exactly one line
(no ``resource_tracker`` KeyError tracebacks, no distributed log lines), nothing written, no process left."""

from __future__ import annotations

import os
import signal
import socket
import time

import pytest

from conftest import hpe, hpe_popen
from hpe_cli.pipelines import dask_runner

from .conftest import SYNTH, check_failed, temp_files
from .test_runs_resume_workers import _alive, _children, _sequence


@pytest.fixture
def silent():
    """A listener that accepts TCP connections (kernel backlog) and never says anything."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(16)
    yield f"tcp://127.0.0.1:{s.getsockname()[1]}"
    s.close()


@pytest.fixture
def refused():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    return f"tcp://127.0.0.1:{port}"


@pytest.mark.parametrize("which,reason", [("silent", "sent nothing within 1 s"), ("refused", "connection refused")])
def test_scheduler_address_fails_in_seconds(tmp_path, monkeypatch, request, which, reason):
    monkeypatch.setattr(dask_runner, "CONNECT_SECONDS", 1.0)
    address = request.getfixturevalue(which)
    t0 = time.monotonic()
    res = hpe("relabel-panoptic", SYNTH, "-o", tmp_path / "o.parquet", "--scheduler", address)
    assert time.monotonic() - t0 < 10
    line = check_failed(res, must_name=address)
    assert reason in line, line
    assert os.listdir(tmp_path) == []


def test_sigterm_during_a_local_cluster_run(tmp_path):
    pytest.importorskip("distributed")
    seq = _sequence(tmp_path / "in", frames=200)
    dst = tmp_path / "out"
    dst.mkdir()
    proc = hpe_popen("relabel-panoptic", seq, "-o", dst / "o.parquet", "--scheduler", "local", "--workers", "2", "-q")
    parts = dst / ".o.parquet.hpe-parts"
    end = time.monotonic() + 90
    while time.monotonic() < end and proc.poll() is None:
        if parts.is_dir() and any(parts.glob("[0-9]*-[0-9]*.json")):
            break
        time.sleep(0.01)
    assert proc.poll() is None, proc.communicate()[1].decode()
    kids = _children(proc.pid)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    err = err.decode()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert err.strip().splitlines() == ["Error: interrupted (SIGTERM)"], err
    assert os.listdir(dst) == [] and not temp_files(dst)
    time.sleep(1.0)
    assert not [k for k in kids if _alive(k)], "Dask processes left running"
