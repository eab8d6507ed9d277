"""Signals and concurrency, in real subprocesses (``python -m hpe_cli``).

SIGTERM, SIGHUP and SIGINT sent mid-run: exit 128+signal, one line ``Error: interrupted (SIG...)``, no
temp file or folder left, no output, no worker process left behind. Two runs creating one output
without --overwrite: exactly one succeeds.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import hpe_popen, hpe_process

from .conftest import SYNTH, temp_files, tree
from .conftest import alive as _alive
from .conftest import children as _children

SIGNALS = [signal.SIGTERM, signal.SIGHUP, signal.SIGINT]


def _wait_for(cond, proc, timeout=60.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            return False
        if cond():
            return True
        time.sleep(0.01)
    return False


def _interrupt(proc, sig, folder, snap, children=()):
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        alive = proc.poll() is None
        info = {c: open(f"/proc/{c}/cmdline").read().replace("\0", " ")[:80] for c in _children(proc.pid) if _alive(c)}
        left = [c for c in children if _alive(c)]
        proc.kill()
        pytest.fail(
            f"no exit 60 s after {signal.Signals(sig).name}: parent alive={alive}, its children={info}, "
            f"workers alive={left}"
        )
    assert proc.returncode == 128 + sig, err
    lines = err.decode(errors="replace").strip().splitlines()
    assert lines == [f"Error: interrupted ({signal.Signals(sig).name})"], err
    assert not temp_files(folder)
    assert tree(folder) == snap
    time.sleep(0.2)
    assert not [c for c in children if _alive(c)], "worker processes left running"


@pytest.fixture(scope="module")
def big_parquet(tmp_path_factory):
    path = tmp_path_factory.mktemp("big") / "big.parquet"
    rng = np.random.default_rng(0)
    n = 400_000
    pq.write_table(
        pa.table({"pitch": rng.uniform(-80, 80, n), "yaw": rng.uniform(-80, 80, n), "roll": rng.uniform(-80, 80, n)}),
        path,
    )
    return path


@pytest.mark.parametrize("sig", SIGNALS)
def test_signal_mid_convert(tmp_path, big_parquet, sig):
    src = tmp_path / "in.parquet"
    shutil.copy(big_parquet, src)
    snap = tree(tmp_path)
    proc = hpe_popen(
        "convert",
        src,
        "-o",
        tmp_path / "out.csv",
        "--from",
        "300w_lp",
        "--to",
        "6drepnet",
        "--batch-size",
        "2000",
        "--rejects",
        tmp_path / "rej.csv",
    )
    if not _wait_for(lambda: temp_files(tmp_path), proc):
        pytest.fail("the run ended before it was interrupted: " + proc.communicate()[1].decode())
    _interrupt(proc, sig, tmp_path, snap)


def _long_sequence(dst: Path, frames: int = 260) -> Path:
    seq = dst / "seq"
    (seq / "hdFace3d").mkdir(parents=True)
    shutil.copy(SYNTH / f"calibration_{SYNTH.name}.json", seq / f"calibration_{SYNTH.name}.json")
    faces = sorted((SYNTH / "hdFace3d").glob("faceRecon3D_hd*.json"))
    for k in range(frames):
        shutil.copy(faces[k % len(faces)], seq / "hdFace3d" / f"faceRecon3D_hd{k:08d}.json")
    os.rename(seq, dst / SYNTH.name)
    return dst / SYNTH.name


@pytest.mark.parametrize("sig,output", [(signal.SIGTERM, "labels.parquet"), (signal.SIGTERM, "train.json")])
def test_signal_stops_relabel_workers(tmp_path, sig, output):
    """Parquet, and COCO whose text the workers make in a second task per unit (parts and text parts)."""
    seq = _long_sequence(tmp_path)
    snap = tree(tmp_path)
    proc = hpe_popen(
        "relabel-panoptic", seq, "-o", tmp_path / output, "--workers", "2", "--rejects", tmp_path / "rej.csv", "-q"
    )
    parts = tmp_path / f".{output}.hpe-parts"
    if not _wait_for(lambda: len(_children(proc.pid)) >= 2 and parts.is_dir() and any(parts.iterdir()), proc):
        pytest.fail("no workers or parts seen: " + proc.communicate()[1].decode())
    kids = _children(proc.pid)
    _interrupt(proc, sig, tmp_path, snap, kids)


def test_signal_stops_infer_user_code(tmp_path):
    code = tmp_path / "slow.py"
    code.write_text("import time\ndef f(p, y, r):\n    time.sleep(600)\n")
    snap = tree(tmp_path)
    proc = hpe_popen("infer", "--callable", f"{code}:f", "--json", tmp_path / "r.json")
    if not _wait_for(lambda: len(_children(proc.pid)) >= 1, proc):
        pytest.fail("no child seen: " + proc.communicate()[1].decode())
    time.sleep(0.3)
    kids = _children(proc.pid)
    _interrupt(proc, signal.SIGTERM, tmp_path, snap, kids)


def test_concurrent_creates_one_winner(tmp_path, big_parquet):
    src = tmp_path / "in.parquet"
    pq.write_table(pq.read_table(big_parquet).slice(0, 5_000), src)
    out = tmp_path / "out.parquet"
    procs = [hpe_popen("convert", src, "-o", out, "--from", "300w_lp", "--to", "6drepnet", "-q") for _ in range(2)]
    results = [(p.wait(timeout=120), p.stderr.read().decode()) for p in procs]
    codes = sorted(c for c, _ in results)
    assert codes == [0, 1], results
    for c, err in results:
        if c:
            assert err.count("Error:") == 1 and "already exists" in err and str(out) in err, err
    assert not temp_files(tmp_path)
    assert pq.read_table(out).num_rows == 5_000


def test_file_size_limit_is_a_clean_error(tmp_path, big_parquet):
    """A real write failure from the OS (RLIMIT_FSIZE: EFBIG) names the output and leaves nothing."""
    import resource

    src = tmp_path / "in.parquet"
    pq.write_table(pq.read_table(big_parquet).slice(0, 20_000), src)
    snap = tree(tmp_path)

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    res = hpe_process(
        "convert", src, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "6drepnet",
        text=False, env={"PYTHONDONTWRITEBYTECODE": "1"}, preexec_fn=limit,
    )  # fmt: skip
    err = res.stderr.decode()
    assert res.returncode == 1, err
    assert err.strip().count("\n") == 0 and str(tmp_path / "o.csv") in err and "too large" in err, err
    assert not temp_files(tmp_path) and tree(tmp_path) == snap
