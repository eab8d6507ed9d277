"""Runs that survive their own processes dying (relabel-panoptic, real subprocesses).

- ``kill -9`` of the parent mid-run: no worker process is left; ``--resume`` then removes the killed run's
  temp files and gives the bytes of an uninterrupted run, with nothing left behind;
- an input edited between the runs (the calibration) is refused by ``--resume``, naming the file;
- a damaged or missing part is named (not ``internal error ArrowInvalid``, not blamed on the rejects file);
- ``kill -9`` of one worker: one clear error line, nothing written.
"""

from __future__ import annotations

import os
import shutil
import signal
import time
from pathlib import Path

import pytest

from conftest import hpe, hpe_popen

from .conftest import SYNTH, temp_files
from .conftest import alive as _alive
from .conftest import children as _children


def _sequence(dst: Path, frames: int = 200) -> Path:
    seq = dst / SYNTH.name
    (seq / "hdFace3d").mkdir(parents=True)
    shutil.copy(SYNTH / f"calibration_{SYNTH.name}.json", seq)
    faces = sorted((SYNTH / "hdFace3d").glob("faceRecon3D_hd*.json"))
    for k in range(frames):
        shutil.copy(faces[k % len(faces)], seq / "hdFace3d" / f"faceRecon3D_hd{k:08d}.json")
    return seq


def _args(seq, out, rej):
    return ["relabel-panoptic", str(seq), "-o", str(out), "--rejects", str(rej), "--workers", "2", "--resume", "-q"]


def _start_and_kill(seq, out, rej, parts_needed=2):
    proc = hpe_popen(*_args(seq, out, rej))
    parts = out.parent / f".{out.name}.hpe-parts"
    end = time.monotonic() + 60
    while time.monotonic() < end and proc.poll() is None:
        if parts.is_dir() and len(list(parts.glob("[0-9]*-[0-9]*.json"))) >= parts_needed and temp_files(out.parent):
            break
        time.sleep(0.005)
    assert proc.poll() is None, "the run ended before it could be killed: " + proc.communicate()[1].decode()
    kids = _children(proc.pid)
    assert len(kids) >= 2, kids
    proc.kill()
    proc.wait()
    return kids


def test_kill9_then_resume_is_byte_identical_and_leaves_nothing(tmp_path):
    seq = _sequence(tmp_path / "in")
    ref_dir, dst = tmp_path / "ref", tmp_path / "out"
    ref_dir.mkdir()
    dst.mkdir()
    res = hpe(*_args(seq, ref_dir / "o.parquet", ref_dir / "r.csv"))
    assert res.exit_code == 0, res.output
    out, rej = dst / "o.parquet", dst / "r.csv"
    kids = _start_and_kill(seq, out, rej)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and any(_alive(k) for k in kids):
        time.sleep(0.05)
    assert not [k for k in kids if _alive(k)], "workers outlived their parent (kill -9)"
    assert temp_files(dst)  # the killed run's staged outputs (and its parts) are there
    res = hpe(*_args(seq, out, rej))
    assert res.exit_code == 0, res.output
    assert out.read_bytes() == (ref_dir / "o.parquet").read_bytes()
    assert rej.read_bytes() == (ref_dir / "r.csv").read_bytes()
    assert sorted(os.listdir(dst)) == ["o.parquet", "r.csv"]  # no temp file, no parts folder


def test_resume_refuses_an_edited_calibration_and_names_damaged_parts(tmp_path):
    seq = _sequence(tmp_path / "in", frames=140)
    dst = tmp_path / "out"
    dst.mkdir()
    out, rej = dst / "o.parquet", dst / "r.csv"
    _start_and_kill(seq, out, rej, parts_needed=1)
    parts = dst / ".o.parquet.hpe-parts"
    time.sleep(0.5)
    done = sorted(parts.glob("*-*.json"))
    assert done
    cal = seq / f"calibration_{SYNTH.name}.json"
    original = cal.read_bytes()
    cal.write_bytes(original.replace(b'"K"', b'"K" ', 1) if b'"K"' in original else original + b" ")
    res = hpe(*_args(seq, out, rej))
    assert (
        res.exit_code == 1
        and str(cal) in res.output
        and "changed since the interrupted run" in res.output
        and "contents" in res.output
    ), res.output
    cal.write_bytes(original)
    labels = Path(str(done[0])[: -len(".json")] + ".labels.arrow")
    labels.write_bytes(labels.read_bytes()[:100])  # cut short
    res = hpe(*_args(seq, out, rej))
    assert res.exit_code == 1 and str(labels) in res.output and "damaged part" in res.output, res.output
    assert "internal error" not in res.output
    labels.unlink()
    res = hpe(*_args(seq, out, rej))
    assert res.exit_code == 1 and str(labels) in res.output and "missing part" in res.output, res.output
    assert str(rej) not in res.output
    shutil.rmtree(parts)
    for t in temp_files(dst):
        os.unlink(t)


def test_a_killed_worker_is_one_clear_error(tmp_path):
    seq = _sequence(tmp_path / "in")
    dst = tmp_path / "out"
    dst.mkdir()
    out = dst / "o.parquet"
    proc = hpe_popen("relabel-panoptic", seq, "-o", out, "--workers", "2", "-q")
    parts = dst / ".o.parquet.hpe-parts"
    end = time.monotonic() + 60
    while time.monotonic() < end and proc.poll() is None:
        if parts.is_dir() and any(parts.glob("[0-9]*-[0-9]*.json")):
            break
        time.sleep(0.005)
    kids = sorted(_children(proc.pid))
    assert kids and proc.poll() is None
    os.kill(kids[-1], signal.SIGKILL)
    _, err = proc.communicate(timeout=60)
    err = err.decode()
    assert proc.returncode == 1, err
    assert err.strip().splitlines() == [err.strip()] and "worker process died" in err, err
    assert "internal error" not in err and "Traceback" not in err
    assert os.listdir(dst) == []
    time.sleep(0.3)
    assert not [k for k in kids if _alive(k)]


@pytest.mark.parametrize("extra", [["--workers", "2"], ["--workers", "2", "--resume"]])
def test_two_runs_writing_one_output_at_once(tmp_path, extra):
    """Both start together: one writes the output, the other stops with one line (the parts folder is
    locked, or the output exists by then); the output is never a mix of the two."""
    seq = _sequence(tmp_path / "in", frames=150)
    ref = tmp_path / "ref.parquet"
    assert hpe("relabel-panoptic", seq, "-o", ref, "-q").exit_code == 0
    dst = tmp_path / "out"
    dst.mkdir()
    out = dst / "o.parquet"
    procs = [hpe_popen("relabel-panoptic", seq, "-o", out, "-q", *extra) for _ in range(2)]
    results = [(p.wait(timeout=120), p.stderr.read().decode()) for p in procs]
    assert sorted(c for c, _ in results) == [0, 1], results
    err = next(e for c, e in results if c)
    assert err.count("\n") == 1 and err.startswith("Error: ") and str(out) in err, err
    assert "another hpe run is writing this output" in err or "already exists" in err, err
    assert out.read_bytes() == ref.read_bytes()
    assert sorted(os.listdir(dst)) == ["o.parquet"]
