"""Panoptic as downloaded: hdFace3d.tar in place, hdVideos, several sequences, units with parts
(workers, resume, Dask), sampling rules and geometry validation. Oracles: the extracted folder,
frames that encode their own number, an uninterrupted single-process run, and hand counts."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import hpe, sample_data_script
from hpe_cli.datasets import panoptic as pan
from hpe_cli.datasets.panoptic_video import VideoFrames
from hpe_cli.errors import HpeError
from hpe_cli.pipelines import parts as folder
from hpe_cli.pipelines.relabel import panoptic as job
from hpe_cli.pipelines.relabel import plan as planning
from hpe_cli.pipelines.relabel import units
from hpe_cli.pipelines.relabel.options import RelabelPanopticOptions

ROOT = Path(__file__).resolve().parents[2]


GEN = sample_data_script()


@pytest.fixture(scope="module")
def seqs(tmp_path_factory):
    """seqA as a folder (with gaps and edge cases), seqA_tar the same packed, seqB another sequence."""
    root = tmp_path_factory.mktemp("pan")
    GEN.make_synthetic(root / "folder" / "seqA", n_frames=20, n_people=2, n_cameras=3, first_frame=3)
    shutil.copytree(root / "folder" / "seqA", root / "tar" / "seqA")
    GEN.pack_tar(root / "tar" / "seqA")
    GEN.make_synthetic(root / "multi" / "seqB", n_frames=8, n_people=2, n_cameras=3, seed=5, special=False)
    shutil.copytree(root / "folder" / "seqA", root / "multi" / "seqA")
    return root


def _read(path):
    return pq.read_table(path)


def test_tar_gives_the_folder_labels(seqs, tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    hpe("relabel-panoptic", seqs / "folder" / "seqA", "-o", a, "-q", ok=True).output
    hpe("relabel-panoptic", seqs / "tar" / "seqA", "-o", b, "-q", ok=True).output
    assert _read(a).equals(_read(b)) and _read(a).num_rows > 50
    frames = pan.face_sources(seqs / "tar" / "seqA")
    assert {7, 8, 14}.isdisjoint(frames) and min(frames) == 3  # gaps are fine
    assert all(r.member.startswith("hdFace3d/") for r in frames.values())


def test_duplicate_frames_name_both(seqs, tmp_path):
    seq = tmp_path / "dup"
    shutil.copytree(seqs / "folder" / "seqA", seq)
    src = seq / "hdFace3d" / "faceRecon3D_hd00000006.json"
    shutil.copy(src, seq / "hdFace3d" / "faceRecon3D_hd6.json")
    with pytest.raises(HpeError, match=r"faceRecon3D_hd00000006\.json and .*faceRecon3D_hd6\.json: both are frame 6"):
        pan.face_frames(seq)
    (seq / "hdFace3d" / "faceRecon3D_hd6.json").unlink()
    GEN.pack_tar(seq, duplicate=6)
    with pytest.raises(
        HpeError,
        match=r"members hdFace3d/faceRecon3D_hd00000006\.json and "
        r"hdFace3d/faceRecon3D_hd6\.json are both frame 6",
    ):
        pan.tar_frames(seq / "hdFace3d.tar")
    out = hpe("relabel-panoptic", seq, "-o", tmp_path / "o.parquet", code=1).output
    assert "both frame 6" in out and "Traceback" not in out


def test_truncated_tar_rejects_the_cut_frame(seqs, tmp_path):
    seq = tmp_path / "cut"
    shutil.copytree(seqs / "tar" / "seqA", seq)
    tar = seq / "hdFace3d.tar"
    frames = pan.tar_frames(tar)
    last = max(frames)
    ref = frames[last]
    data = tar.read_bytes()
    tar.write_bytes(data[: ref.offset + ref.size // 2])  # cut inside the last member's data
    cut = pan.tar_frames(tar)
    assert cut[last].truncated and not any(r.truncated for k, r in cut.items() if k != last)
    o, rj = tmp_path / "o.parquet", tmp_path / "r.csv"
    out = hpe("relabel-panoptic", seq, "-o", o, "--rejects", rj, ok=True).output
    assert "1 unreadable (truncated) face files" in out
    import pandas as pd

    rej = pd.read_csv(rj)
    row = rej[rej["reason"] == "truncated face file"]
    assert list(row["frame"]) == [last] and "archive ends first" in row["detail"].iloc[0]
    assert last not in set(_read(o).column("frame").to_pylist())
    tar.write_bytes(b"not a tar at all" * 10)
    with pytest.raises(HpeError, match="not a readable tar"):
        pan.tar_frames(tar)


def test_several_sequences_and_a_root(seqs, tmp_path):
    o1, o2 = tmp_path / "1.parquet", tmp_path / "2.parquet"
    out = hpe("relabel-panoptic", seqs / "multi" / "seqA", seqs / "multi" / "seqB", "-o", o1, ok=True).output
    assert out.count("seqA: ") == 1 and out.count("seqB: ") == 1 and "total over 2 sequences" in out
    hpe("relabel-panoptic", seqs / "multi", "-o", o2, "-q", ok=True).output
    t = _read(o1)
    assert t.equals(_read(o2))
    assert list(dict.fromkeys(t.column("sequence").to_pylist())) == ["seqA", "seqB"]
    one = _read(_one(seqs / "multi" / "seqB", tmp_path))
    sub = t.filter(np.asarray(t.column("sequence").to_pylist()) == "seqB")
    assert sub.equals(one)
    out = hpe(
        "relabel-panoptic", seqs / "multi" / "seqA", seqs / "multi" / "seqA", "-o", tmp_path / "3.parquet", code=1
    ).output
    assert "given twice" in out


def _one(seq, tmp_path):
    o = tmp_path / f"one_{seq.name}.parquet"
    hpe("relabel-panoptic", seq, "-o", o, "-q", ok=True).output
    return o


def test_same_bytes_with_workers_resume_and_dask(seqs, tmp_path):
    seq = seqs / "tar" / "seqA"
    plans = planning.plan_many([seq], chunk_frames=4)
    opts = RelabelPanopticOptions(landmarks=False)
    ref = tmp_path / "ref.parquet"
    job.write_outputs(plans, ref, replace(opts, rejects=tmp_path / "ref_rej.parquet"))
    two = tmp_path / "two.parquet"
    job.write_outputs(plans, two, replace(opts, workers=2, rejects=tmp_path / "two_rej.parquet"))
    assert ref.read_bytes() == two.read_bytes()
    assert (tmp_path / "ref_rej.parquet").read_bytes() == (tmp_path / "two_rej.parquet").read_bytes()
    assert not folder.parts_dir_for(two).exists()
    # an interrupted run: some units finished, one half-written, then --resume
    res = tmp_path / "res.parquet"
    parts = units.prepare_unit_parts(plans, opts.config(), "table", res, resume=False)
    tasks = [units.unit_task(plans, opts.config(), u, parts) for u in units.make_units(plans)]
    for t in tasks[:2]:
        job.run_unit(t)
    Path(tasks[2]["stem"] + ".labels.arrow.tmp").write_bytes(b"half")
    calls = []
    real = job.run_unit

    def counting(task):
        calls.append(task["stem"])
        return real(task)

    job.run_unit = counting
    try:
        job.write_outputs(plans, res, replace(opts, resume=True))
    finally:
        job.run_unit = real
    assert len(calls) == len(tasks) - 2
    assert res.read_bytes() == ref.read_bytes()
    # resuming with other options is refused
    units.prepare_unit_parts(
        plans, opts.config(), "table", res, resume=False, overwrite=True
    )  # next to the finished output
    with pytest.raises(HpeError, match="other inputs or options"):
        job.write_outputs(plans, res, replace(RelabelPanopticOptions(landmarks=True), resume=True, overwrite=True))
    shutil.rmtree(folder.parts_dir_for(res))


def test_same_bytes_on_a_local_dask_cluster(seqs, tmp_path):
    pytest.importorskip("dask.distributed")
    seq = seqs / "multi" / "seqB"
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    hpe("relabel-panoptic", seq, "-o", a, "-q", "--no-landmarks", ok=True).output
    hpe(
        "relabel-panoptic", seq, "-o", b, "-q", "--no-landmarks", "--scheduler", "local", "--workers", "2", ok=True
    ).output
    assert a.read_bytes() == b.read_bytes()


def test_no_landmarks_drops_only_the_landmark_columns(seqs, tmp_path):
    seq = seqs / "multi" / "seqB"
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    hpe("relabel-panoptic", seq, "-o", a, "-q", ok=True).output
    hpe("relabel-panoptic", seq, "-o", b, "-q", "--no-landmarks", ok=True).output
    ta, tb = _read(a), _read(b)
    assert [c for c in ta.column_names if not c.startswith("lm")] == tb.column_names
    assert ta.select(tb.column_names).equals(tb)


# ------------------------------------------------------------------ videos
@pytest.fixture(scope="module")
def video_seq(tmp_path_factory):
    root = tmp_path_factory.mktemp("vid") / "seqV"
    GEN.make_synthetic(root, n_frames=12, n_people=1, n_cameras=2, first_frame=2, special=False)
    GEN.write_videos(root, last_frame=10, size=(192, 108))  # frames 11..13 are past the end
    return root


def test_video_frames_are_hd_frame_numbers(video_seq):
    v = VideoFrames(pan.hd_video_path(video_seq, "00_01"))
    got = list(v.read([12, 0, 5, 10, 5, 11, 13]))
    assert [f for f, _, _ in got] == [0, 5, 10, 11, 12, 13]
    for f, img, reason in got:
        if f <= 10:
            assert reason == "" and img.shape == (108, 192, 3) and GEN.decode_frame_number(img) == f
        else:
            assert img is None and reason == "past the end of the video (11 frames)"


def test_truncated_or_missing_video_rejects_every_frame(video_seq, tmp_path):
    p = tmp_path / "hd_00_00.mp4"
    data = pan.hd_video_path(video_seq, "00_00").read_bytes()
    p.write_bytes(data[: len(data) // 2])
    got = list(VideoFrames(p).read([1, 2]))
    assert [(f, img) for f, img, _ in got] == [(1, None), (2, None)]
    assert "cannot open the video hd_00_00.mp4" in got[0][2]
    assert "no video" in list(VideoFrames(tmp_path / "none.mp4").read([3]))[0][2]


def test_video_and_hdimgs_give_the_same_pixels(video_seq, tmp_path):
    import cv2

    frames = [2, 7]
    d = tmp_path / "hdImgs" / "00_00"
    d.mkdir(parents=True)
    for f, img, _ in VideoFrames(pan.hd_video_path(video_seq, "00_00")).read(frames):
        cv2.imwrite(str(d / f"00_00_{f:08d}.png"), img)
    for f, img, _ in VideoFrames(pan.hd_video_path(video_seq, "00_00")).read(frames):
        path = pan.hd_image_path(tmp_path, "00_00", f)
        assert path == tmp_path / "hdImgs" / "00_00" / f"00_00_{f:08d}.jpg"
        png = cv2.imread(str(path.with_suffix(".png")))
        np.testing.assert_array_equal(png, img)
    with pytest.raises(HpeError, match="camera name"):
        pan.hd_image_path(tmp_path, "../x", 1)


# -------------------------------------------------------------- validation
def _calib(tmp_path, mutate):
    src = ROOT / "sample_data" / "panoptic_synth"
    seq = tmp_path / "bad"
    shutil.copytree(src, seq)
    p = pan.find_calibration(seq)
    c = json.loads(p.read_text())
    mutate(c["cameras"])
    p.write_text(json.dumps(c))
    return p


@pytest.mark.parametrize(
    "mutate,message",
    [
        (lambda cams: cams[1].update(name=cams[0]["name"]), r"camera 0 and camera 1 are both named '00_00'"),
        (lambda cams: cams[0].update(K=[[0, 0, 0], [0, 0, 0], [0, 0, 0]]), r"camera 0 \(00_00\): expected K ="),
        (lambda cams: cams[0].update(resolution=[0, 0]), r"camera 0 \(00_00\): expected a positive resolution"),
        (lambda cams: cams[0].update(name="../../etc"), r"expected a camera name .* got '../../etc'"),
        (lambda cams: cams[0].update(R=[[2, 0, 0], [0, 2, 0], [0, 0, 2]]), r"expected R to be a rotation"),
    ],
)
def test_calibration_validation(tmp_path, mutate, message):
    with pytest.raises(HpeError, match=message):
        pan.read_calibration(_calib(tmp_path, mutate))


def test_absurd_landmarks_are_a_face_reject(tmp_path):
    seq = tmp_path / "abs"
    shutil.copytree(ROOT / "sample_data" / "panoptic_synth", seq)
    f = sorted((seq / "hdFace3d").iterdir())[0]
    d = json.loads(f.read_text())
    d["people"][0]["face70"]["landmarks"][5] = 1e308
    f.write_text(json.dumps(d))
    rj = tmp_path / "r.csv"
    out = hpe("relabel-panoptic", seq, "-o", tmp_path / "o.parquet", "--rejects", rj, ok=True).output
    assert "1 with bad landmarks" in out
    import pandas as pd

    rej = pd.read_csv(rj)
    n_cams = len(pan.read_calibration(pan.find_calibration(seq), "hd"))
    assert (rej["reason"] == "bad landmarks").sum() == n_cams  # one face x every hd camera


@pytest.mark.parametrize("fmt,suffix", [("coco", ".json"), ("whenet", ".txt")])
def test_coco_and_whenet_stream_with_the_same_content(seqs, tmp_path, fmt, suffix):
    seq = seqs / "multi" / "seqB"
    a, b, t = tmp_path / f"a{suffix}", tmp_path / f"b{suffix}", tmp_path / "t.parquet"
    hpe("relabel-panoptic", seq, "-o", a, "-q", "--format", fmt, ok=True).output
    hpe("relabel-panoptic", seq, "-o", b, "-q", "--format", fmt, "--workers", "2", ok=True).output
    assert a.read_bytes() == b.read_bytes()
    hpe("relabel-panoptic", seq, "-o", t, "-q", "--system", "whenet", ok=True).output
    frame = _read(t).to_pandas()
    ref = tmp_path / f"ref{suffix}"
    if fmt == "coco":
        from hpe_cli.io.coco import write_coco

        write_coco(frame, ref, image_size_cols=("image_width", "image_height"), info={"hpe:system": "whenet"})
        assert json.loads(a.read_text()) == json.loads(ref.read_text())
    else:
        from hpe_cli.io.whenet_txt import write_whenet

        write_whenet(frame, ref)
        assert a.read_text() == ref.read_text()


def test_corrupt_header_in_the_middle_is_an_error(seqs, tmp_path):
    tar = tmp_path / "hdFace3d.tar"
    shutil.copy(seqs / "tar" / "seqA" / "hdFace3d.tar", tar)
    refs = list(pan.tar_frames(tar).values())
    mid = refs[len(refs) // 2]
    data = bytearray(tar.read_bytes())
    header = mid.offset - 512
    data[header : header + 512] = b"\x7f" * 512  # garbage where a member header was
    tar.write_bytes(bytes(data))
    with pytest.raises(HpeError, match=r"unreadable member header at byte \d+"):
        pan.tar_frames(tar)
    # cut inside the last member's header: an error, not a silently missing frame
    tar.write_bytes((seqs / "tar" / "seqA" / "hdFace3d.tar").read_bytes()[: refs[-1].offset - 300])
    with pytest.raises(HpeError, match=r"ends inside a member header at byte \d+ \(truncated download\)"):
        pan.tar_frames(tar)
    # cut exactly after a member: no end-of-archive blocks
    tar.write_bytes((seqs / "tar" / "seqA" / "hdFace3d.tar").read_bytes()[: refs[-1].offset - 512])
    with pytest.raises(HpeError, match="without tar's end-of-archive blocks"):
        pan.tar_frames(tar)


def test_a_run_that_ends_between_a_look_and_the_lock_leaves_no_parts_folder(seqs, tmp_path, monkeypatch):
    """Two runs, one output (seen in CI): run B sees A's parts folder, A places the output and removes its folder,
    then B makes a folder of its own and locks it. B must fail with 'already exists' and remove the folder it
    made, not keep it as if it were an interrupted run's (whether the folder was there is read at the lock)."""

    plans = planning.plan_many([seqs / "tar" / "seqA"], chunk_frames=4)
    opts = RelabelPanopticOptions(landmarks=False)
    out = tmp_path / "o.parquet"
    d = folder.parts_dir_for(out)
    d.mkdir()  # run A's parts folder, there when B looks
    real = folder._make

    def a_ends_first(folder):
        shutil.rmtree(d)  # A: done, output placed, its parts folder removed
        out.write_bytes(b"A's output")
        return real(folder)  # B makes a new folder

    monkeypatch.setattr(folder, "_make", a_ends_first)
    for resume in (True, False):
        d.mkdir(exist_ok=True)
        out.unlink(missing_ok=True)
        with pytest.raises(HpeError, match="already exists"):
            units.prepare_unit_parts(plans, opts.config(), "table", out, resume=resume)
        assert not d.exists() and out.read_bytes() == b"A's output"
