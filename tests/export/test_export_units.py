"""``hpe export`` in units: ``--workers``, ``--scheduler local`` (Dask) and ``--resume`` write the bytes of a
one-process run, for every layout, on a synthetic multi-sequence release made from videos (:mod:`release`).

Oracles: the one-process export (the same bytes, file by file); OpenCV's sequential decoding of the video
(the frame a seek lands on, read back from the frame number drawn in it); the release's own geometry (the
second sequence's videos end three frames early, so exactly those labels are rejects naming the video and the
frame); scipy's ``loadmat`` for the pinned ``.mat`` header.
"""

from __future__ import annotations

import os
import socket
import time

import numpy as np
import pandas as pd
import pytest
import scipy.io
from release import LAYOUT_IDS, export_args, make_release, sample_data_script, tree

from conftest import hpe
from hpe_cli.pipelines.export import units as U


@pytest.fixture(scope="module")
def release(tmp_path_factory):
    return make_release(tmp_path_factory.mktemp("release"))


@pytest.fixture(scope="module")
def reference(release, tmp_path_factory):
    """layout id -> (tree of the one-process export, its rejects' bytes)."""
    root, labels = release
    d = tmp_path_factory.mktemp("reference")
    out = {}
    for lid in LAYOUT_IDS:
        res = hpe(*export_args(lid, labels, root, d / lid, d / f"{lid}.csv"))
        assert res.exit_code == 0, res.output
        out[lid] = (tree(d / lid), (d / f"{lid}.csv").read_bytes())
    return out


def _same(reference, lid, out, rej):
    assert tree(out) == reference[lid][0]
    assert rej.read_bytes() == reference[lid][1]


@pytest.mark.parametrize("lid", LAYOUT_IDS)
def test_workers_give_the_one_process_bytes(release, reference, tmp_path, lid):
    root, labels = release
    res = hpe(*export_args(lid, labels, root, tmp_path / "o", tmp_path / "r.csv", "--workers", "2"))
    assert res.exit_code == 0, res.output
    _same(reference, lid, tmp_path / "o", tmp_path / "r.csv")
    assert sorted(os.listdir(tmp_path)) == ["o", "r.csv"]


@pytest.mark.parametrize("lid", LAYOUT_IDS)
def test_local_cluster_gives_the_one_process_bytes(release, reference, tmp_path, lid):
    pytest.importorskip("distributed")
    root, labels = release
    args = export_args(lid, labels, root, tmp_path / "o", tmp_path / "r.csv", "--scheduler", "local", "--workers", "2")
    res = hpe(*args)
    assert res.exit_code == 0, res.output
    _same(reference, lid, tmp_path / "o", tmp_path / "r.csv")
    assert sorted(os.listdir(tmp_path)) == ["o", "r.csv"]  # no parts folder, no temp file


def test_two_runs_write_the_same_mat_files(release, reference, tmp_path):
    """The .mat header's text is pinned (scipy writes the time there); loadmat reads the files as before."""
    root, labels = release
    res = hpe(*export_args("6drepnet", labels, root, tmp_path / "o", tmp_path / "r.csv"))
    assert res.exit_code == 0, res.output
    _same(reference, "6drepnet", tmp_path / "o", tmp_path / "r.csv")
    mats = sorted((tmp_path / "o").rglob("*.mat"))
    assert mats
    head = mats[0].read_bytes()[:128]
    assert head[:116].rstrip(b"\0") == b"MATLAB 5.0 MAT-file Platform: posix, Created on: Thu Jan  1 00:00:00 1970"
    m = scipy.io.loadmat(mats[0])
    assert m["Pose_Para"].shape == (1, 7) and m["pt2d"].shape[0] == 2


def test_short_video_rows_are_rejects_naming_video_and_frame(release, reference, tmp_path):
    """seqB's videos have frames 0..8, its labels 0..11: exactly those 3 frames x 3 cameras x 2 people are
    rejects (each naming seqB's own video and the frame), and seqA, whose images have the same names, is not
    taken for seqB."""
    root, labels = release
    res = hpe(*export_args("hf", labels, root, tmp_path / "o", tmp_path / "r.csv"))
    assert res.exit_code == 0, res.output
    rej = pd.read_csv(tmp_path / "r.csv")
    assert len(rej) == 18
    assert set(rej["sequence"]) == {"seqB"} and set(rej["frame"]) == {9, 10, 11}
    for _, r in rej.iterrows():
        video = str(root / "seqB" / "hdVideos" / f"hd_{r['camera']}.mp4")
        assert r["reason"] == f"no image (video {video} frame {r['frame']}: past the end of the video (9 frames))"
    crops = pd.read_csv(tmp_path / "o" / "crops.csv")
    lab = pd.read_parquet(labels)
    assert len(crops) == len(lab) - 18


def test_a_seek_lands_on_the_frame_asked_for(tmp_path):
    """VideoFrames.read(seek=True) gives the frames (and pixels) of sequential decoding."""
    cv2 = pytest.importorskip("cv2")
    from hpe_cli.datasets.panoptic_video import VideoFrames

    mk = sample_data_script()
    (tmp_path / "s").mkdir()
    path = tmp_path / "v.mp4"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 29.97, (192, 108))
    if not w.isOpened():
        pytest.skip("OpenCV cannot write mp4 here")
    for k in range(40):
        w.write(mk.encode_frame_number(k))
    w.release()
    seq = {f: img for f, img, _ in VideoFrames(path).read(range(40))}
    got = list(VideoFrames(path).read([17, 18, 30, 39, 40, 45], seek=True))
    assert [f for f, _, _ in got] == [17, 18, 30, 39, 40, 45]
    for f, img, reason in got[:4]:
        assert reason == "" and mk.decode_frame_number(img) == f and np.array_equal(img, seq[f])
    assert [r for _, _, r in got[4:]] == ["past the end of the video (40 frames)"] * 2
    assert [r for _, _, r in VideoFrames(path).read([41], seek=True)] == ["past the end of the video (40 frames)"]


def test_small_blocks_give_the_same_bytes(release, reference, tmp_path, monkeypatch):
    """Units of 4 frames (each block one seek into the video) write what whole-video units write."""
    monkeypatch.setattr(U, "BLOCK_FRAMES", 4)
    root, labels = release
    res = hpe(*export_args("hf", labels, root, tmp_path / "o", tmp_path / "r.csv"))
    assert res.exit_code == 0, res.output
    _same(reference, "hf", tmp_path / "o", tmp_path / "r.csv")


def test_resume_keeps_finished_units_and_refuses_a_changed_video(release, reference, tmp_path, monkeypatch):
    from hpe_cli.errors import HpeError
    from hpe_cli.pipelines.export import write

    root, labels = release
    out, rej = tmp_path / "o", tmp_path / "r.csv"
    args = export_args("whenet", labels, root, out, rej, "--resume")

    def fail(*a, **k):
        raise HpeError("stopped on purpose")

    with monkeypatch.context() as m:
        m.setattr(write, "write_index", fail)
        res = hpe(*args)
    assert res.exit_code == 1 and "stopped on purpose" in res.output
    parts = tmp_path / ".o.hpe-parts"
    assert len(list(parts.glob("[0-9]*.json"))) == 6  # 2 sequences x 3 videos, one block each
    assert not out.exists() and not [n for n in os.listdir(tmp_path) if n.startswith(".hpe-")]

    video = root / "seqA" / "hdVideos" / "hd_00_01.mp4"
    st = os.stat(video)
    os.utime(video, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    try:
        res = hpe(*args)
        assert res.exit_code == 1, res.output
        line = res.output.strip().splitlines()[-1]
        assert line.startswith(f"Error: {video}: changed since the interrupted run"), line
        assert "size, modification time and inode" in line
    finally:
        os.utime(video, ns=(st.st_atime_ns, st.st_mtime_ns))

    with monkeypatch.context() as m:  # every unit is done: none is computed again
        m.setattr(U, "run_unit", lambda task: pytest.fail("a finished unit was computed again"))
        res = hpe(*args)
    assert res.exit_code == 0, res.output
    _same(reference, "whenet", out, rej)
    assert sorted(os.listdir(tmp_path)) == ["o", "r.csv"]


def test_resume_names_a_damaged_part(release, tmp_path, monkeypatch):
    from hpe_cli.errors import HpeError
    from hpe_cli.pipelines.export import write

    root, labels = release
    args = export_args("hf", labels, root, tmp_path / "o", tmp_path / "r.csv", "--resume")
    with monkeypatch.context() as m:
        m.setattr(write, "write_index", lambda *a, **k: (_ for _ in ()).throw(HpeError("stop")))
        assert hpe(*args).exit_code == 1
    spill = tmp_path / ".o.hpe-parts" / "000001.spill"
    spill.write_bytes(spill.read_bytes()[:10])
    res = hpe(*args)
    assert res.exit_code == 1
    assert f"Error: {spill}: damaged part of the interrupted run" in res.output, res.output


def test_scheduler_unreachable_is_one_line_in_seconds(release, tmp_path):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    root, labels = release
    t0 = time.monotonic()
    address = f"tcp://127.0.0.1:{port}"
    res = hpe(*export_args("whenet", labels, root, tmp_path / "o", tmp_path / "r.csv", "--scheduler", address))
    assert time.monotonic() - t0 < 10
    assert res.exit_code == 1
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert errors == [f"Error: --scheduler {address}: cannot connect (connection refused)"], res.output
    assert os.listdir(tmp_path) == []


def test_a_unit_reads_relative_sources_from_the_runs_folder(tmp_path, monkeypatch):
    """A Dask worker runs in another folder: a unit reads a relative image path from the folder the run was
    started in (the task's ``cwd``), and names it as given."""
    import cv2

    (tmp_path / "run" / "img").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "run" / "img" / "a.jpg"), np.full((60, 80, 3), 90, np.uint8))
    monkeypatch.chdir(tmp_path / "run")
    cfg = {
        "root": str(tmp_path / "stage"),
        "split_dirs": {"train": "train"},
        "quality": 95,
        "pad_value": 0,
        "min_inside": 0.5,
        "full_frames": False,
        "pixels": "file",
    }
    items = [(0, "train", "a.jpg", (10, 10, 40, 40), (10.0, 10.0, 30.0, 30.0), (30, 30), None)]
    missing = [(1, "train", "b.jpg", (10, 10, 40, 40), (10.0, 10.0, 30.0, 30.0), (30, 30), None)]
    task = U.unit_task(cfg, [["image", "img/a.jpg", items], ["image", "img/b.jpg", missing]], None)
    monkeypatch.chdir(tmp_path)  # the worker's own folder
    res, spill = U.run_unit(task)
    assert spill is None
    assert [r[:2] for r in res] == [(0, ""), (1, "no image (No such file or directory)")]
    assert cv2.imread(str(tmp_path / "stage" / "train" / "a.jpg")).shape == (30, 30, 3)


@pytest.mark.parametrize("gop", [["-g", "30", "-bf", "3"], ["-g", "30", "-bf", "3", "-x264-params", "open-gop=1"]])
def test_a_seek_into_h264_with_b_frames(tmp_path, gop):
    """The HD release is H.264: a seek into a stream with B-frames (closed or open GOPs) gives the frames, and
    pixels, of sequential decoding (needs an ffmpeg with libx264 to make the video)."""
    import shutil
    import subprocess

    cv2 = pytest.importorskip("cv2")
    from hpe_cli.datasets.panoptic_video import VideoFrames

    if shutil.which("ffmpeg") is None:
        pytest.skip("ffmpeg is not installed (it makes the H.264 test video)")
    mk = sample_data_script()
    for k in range(100):
        img = mk.encode_frame_number(k, 384, 216)
        img[:20] = (k * 37) % 256  # motion for the encoder
        cv2.imwrite(str(tmp_path / f"f{k:05d}.png"), img)
    video = tmp_path / "v.mp4"
    cmd = ["ffmpeg", "-loglevel", "error", "-y", "-framerate", "30000/1001", "-i", str(tmp_path / "f%05d.png")]
    r = subprocess.run([*cmd, "-c:v", "libx264", "-pix_fmt", "yuv420p", *gop, str(video)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"ffmpeg cannot encode H.264 here: {r.stderr.decode()[-200:]}")
    seq = {f: img for f, img, _ in VideoFrames(video).read(range(100))}
    assert all(mk.decode_frame_number(img) == f for f, img in seq.items())
    for start in (1, 29, 30, 31, 47, 61, 90):
        for f, img, reason in VideoFrames(video).read(range(start, min(start + 8, 100)), seek=True):
            assert reason == "" and mk.decode_frame_number(img) == f and np.array_equal(img, seq[f]), (start, f)
