"""hpe biwi: RGB camera, head boxes, protocols, sequence splits (real BIWI samples where present)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.datasets.biwi import head_boxes, read_biwi_camera, sequence_split, to_rgb_camera

BIWI = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata" / "biwi"
HPDB = BIWI / "hpdb"
# rgb.cal of sequence 01 and frame_00003_pose.txt, typed from the files (PROVENANCE §4)
K_RGB = np.array([[517.679, 0, 320], [0, 517.679, 240.5], [0, 0, 1]])
R_CAL = np.array(
    [[0.999947, 0.00432361, 0.00929419], [-0.00446314, 0.999877, 0.0150443], [-0.009228, -0.015085, 0.999844]]
)
T_CAL = np.array([-24.0198, 5.8896, -13.2308])
R3 = np.array([[0.997978, 0.0272944, 0.0574071], [-0.0346956, 0.990621, 0.132163], [-0.0532613, -0.133887, 0.989564]])
C3 = np.array([51.9358, 38.2631, 881.756])


def need_hpdb():
    if not (HPDB / "01" / "rgb.cal").exists():
        pytest.skip("real BIWI sample absent")


def test_rgb_camera_frame3_by_hand():
    need_hpdb()
    t = read_biwi_camera(HPDB, camera="rgb")
    R = t[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(3, 3)
    np.testing.assert_allclose(R, R_CAL @ R3, atol=2e-5)  # pose.txt/rgb.cal printed to ~6 digits
    c = R_CAL @ C3 + T_CAL
    np.testing.assert_allclose(t[["center_x", "center_y", "center_z"]].to_numpy()[0], c, atol=1e-3)
    uv = (K_RGB @ c)[:2] / c[2]  # on the bridge of the nose in frame_00003_rgb.png (checked by eye)
    np.testing.assert_allclose(t[["center_u", "center_v"]].to_numpy()[0], uv, atol=2e-3)
    np.testing.assert_allclose(uv, [341.65, 274.63], atol=0.01)
    uv = K_RGB @ t[["center_x", "center_y", "center_z"]].to_numpy()[0]
    uv = uv[:2] / uv[2]
    c = t[["center_x", "center_y", "center_z"]].to_numpy()[0]
    side = 2 * 517.679 * 100 / np.sqrt(c @ c - 100**2)  # 200 mm sphere
    np.testing.assert_allclose(t[["bbox_w", "bbox_h"]].to_numpy()[0], [side, side], atol=1e-9)
    np.testing.assert_allclose(t["bbox_x"].to_numpy()[0], uv[0] - side / 2, atol=1e-6)
    assert t.loc[0, "image"] == "01/frame_00003_rgb.png"


def test_depth_camera_keeps_labels_and_uses_depth_cal():
    need_hpdb()
    t = read_biwi_camera(HPDB, camera="depth")
    np.testing.assert_allclose(
        t[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(3, 3), R3, atol=2e-6
    )
    uv = np.array([[575.816, 0, 320], [0, 575.816, 240], [0, 0, 1]]) @ C3
    np.testing.assert_allclose(t[["center_u", "center_v"]].to_numpy()[0], uv[:2] / uv[2], atol=1e-6)


def test_head_boxes_off_axis_and_behind():
    boxes, uv = head_boxes(np.array([[0.0, 0.0, 1000.0], [300.0, -200.0, 900.0], [0.0, 0.0, -5.0]]), K_RGB)
    np.testing.assert_allclose(uv[0], [320, 240.5])
    np.testing.assert_allclose(uv[1], [320 + 517.679 * 300 / 900, 240.5 - 517.679 * 200 / 900])
    assert np.isnan(boxes[2]).all()


def test_to_rgb_camera_is_a_rotation():
    R, c = to_rgb_camera(np.eye(3)[None], np.zeros((1, 3)), {"R": R_CAL, "t": T_CAL})
    np.testing.assert_allclose(R[0] @ R[0].T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(c[0], T_CAL)


def test_sequence_split_deterministic_disjoint():
    seqs = [f"{i:02d}" for i in range(1, 25)]
    a = sequence_split(seqs * 3, (0.7, 0.3), seed=0)
    assert a == sequence_split(list(reversed(seqs)), (0.7, 0.3), seed=0)
    assert (len(a["train"]), len(a["test"])) == (17, 7)
    assert sorted(a["train"] + a["test"]) == seqs
    b = sequence_split(seqs, (16 / 24, 8 / 24), seed=3)
    assert (len(b["train"]), len(b["test"])) == (16, 8)
    c = sequence_split(seqs, (0.6, 0.2, 0.2), seed=1)
    assert list(c) == ["train", "val", "test"] and sum(map(len, c.values())) == 24


def test_cli_biwi_split_lists_and_protocol(tmp_path):
    tgz = BIWI / "db_annotations.tgz"
    if not tgz.exists():
        pytest.skip("real BIWI annotations absent")
    out, lists = tmp_path / "b.parquet", tmp_path / "splits"
    r = hpe(
        "biwi",
        tgz,
        "-o",
        out,
        "--split",
        "0.7,0.3",
        "--split-lists",
        lists,
        "--protocol",
        "hopenet-99",
        "--system",
        "300w_lp",
        "-q",
    )
    assert r.exit_code == 0, r.output
    f = pd.read_parquet(out)
    assert len(f) == 15677  # no official frame is beyond +-99 deg
    train = (lists / "train_sequences.txt").read_text().split()
    test = (lists / "test_sequences.txt").read_text().split()
    assert len(train) == 17 and len(test) == 7 and not set(train) & set(test)
    assert set(f.loc[f["split"] == "train", "sequence"]) == set(train)
    from hpe_cli.io import open_table

    assert open_table(out).system == "300w_lp"
    r = hpe("biwi", tgz, "-o", out)
    assert r.exit_code == 1 and "exists" in r.output


def test_cli_biwi_rgb_without_calibration(tmp_path):
    sub = BIWI / "db_annotations_subset" / "01"
    if not sub.exists():
        pytest.skip("real BIWI annotations absent")
    d = tmp_path / "ann" / "01"
    d.mkdir(parents=True)
    shutil.copy(sub / "frame_00166_pose.bin", d)
    r = hpe("biwi", tmp_path / "ann", "-o", tmp_path / "o.csv", "--camera", "rgb")
    assert r.exit_code == 1 and "rgb.cal" in r.output and len(r.output.strip().splitlines()) == 1
    if HPDB.exists():
        r = hpe("biwi", tmp_path / "ann", "-o", tmp_path / "o.csv", "--camera", "rgb", "--calibration", HPDB, "-q")
        assert r.exit_code == 0, r.output
        f = pd.read_csv(tmp_path / "o.csv")
        # frame 166's head box (checked by eye on frame_00166_rgb.png) lies inside the 640x480 image
        assert 0 < f.loc[0, "bbox_x"] and f.loc[0, "bbox_x"] + f.loc[0, "bbox_w"] < 640


def _damaged_copy(tmp_path):
    """A copy of the real .bin subset with three damaged frames: truncated, NaN, and a yaw no Z-Y-X split gives."""
    sub = BIWI / "db_annotations_subset"
    if not sub.exists():
        pytest.skip("real BIWI annotations absent")
    ann = tmp_path / "ann"
    shutil.copytree(sub, ann)
    frames = sorted(p.relative_to(ann).as_posix() for p in ann.rglob("frame_*_pose.bin"))
    (ann / "01/frame_00006_pose.bin").write_bytes((ann / "01/frame_00006_pose.bin").read_bytes()[:10])
    v = np.frombuffer((ann / "02/frame_00348_pose.bin").read_bytes(), "<f4").copy()
    v[4] = np.nan
    (ann / "02/frame_00348_pose.bin").write_bytes(v.tobytes())
    v = np.frombuffer((ann / "03/frame_00562_pose.bin").read_bytes(), "<f4").copy()
    v[4] = 120.0
    (ann / "03/frame_00562_pose.bin").write_bytes(v.tobytes())
    return ann, frames


def test_cli_biwi_rejects_damaged_frames(tmp_path):
    """Every frame is in the labels or the rejects (file, reason); the kept ones equal a read of the originals."""
    ann, frames = _damaged_copy(tmp_path)
    out, rej = tmp_path / "o.parquet", tmp_path / "rej.csv"
    r = hpe("biwi", ann, "-o", out, "--system", "300w_lp", "--rejects", rej)
    assert r.exit_code == 0, r.output
    assert "rejected 3 frames" in r.stderr and str(rej) in r.stderr
    labels, rejects = pd.read_parquet(out), pd.read_csv(rej, dtype={"sequence": str})
    assert list(rejects.columns) == ["file", "sequence", "frame", "reason"]
    assert sorted(labels["file"].tolist() + rejects["file"].tolist()) == frames
    assert len(labels) + len(rejects) == len(frames) and not set(labels["file"]) & set(rejects["file"])
    why = dict(zip(rejects["file"], rejects["reason"]))
    assert why == {
        "01/frame_00006_pose.bin": "expected 24 bytes (6 float32), got 10",
        "02/frame_00348_pose.bin": why["02/frame_00348_pose.bin"],
        "03/frame_00562_pose.bin": "yaw: expected degrees within +-90 (a Z-Y-X split), got 120",
    }
    assert why["02/frame_00348_pose.bin"].startswith("expected finite values")
    assert rejects.set_index("file").loc["03/frame_00562_pose.bin", ["sequence", "frame"]].tolist() == ["03", 562]
    whole = read_biwi_camera(BIWI / "db_annotations_subset", system="300w_lp").set_index("file").loc[labels["file"]]
    cols = [f"r{i}{j}" for i in range(3) for j in range(3)] + ["center_x", "center_y", "center_z", "bbox_w"]
    np.testing.assert_allclose(labels[cols].to_numpy(), whole[cols].to_numpy(), atol=1e-12)


def test_cli_biwi_without_rejects_or_strict_writes_nothing(tmp_path):
    ann, _ = _damaged_copy(tmp_path)
    out, rej = tmp_path / "o.csv", tmp_path / "rej.csv"
    r = hpe("biwi", ann, "-o", out)
    assert r.exit_code == 1 and len(r.output.strip().splitlines()) == 1, r.output
    assert f"{ann / '01' / 'frame_00006_pose.bin'}: expected 24 bytes" in r.output and "3 row(s)" in r.output
    assert "--rejects" in r.output and not out.exists()
    r = hpe("biwi", ann, "-o", out, "--rejects", rej, "--strict")
    assert r.exit_code == 1 and "--strict" in r.output and len(r.output.strip().splitlines()) == 1, r.output
    assert not out.exists() and not rej.exists()
    shutil.rmtree(ann)
    shutil.copytree(BIWI / "db_annotations_subset", ann)
    r = hpe("biwi", ann, "-o", out, "--rejects", rej, "--strict", "-q")
    assert r.exit_code == 0, r.output  # nothing rejected: --strict changes nothing
    assert pd.read_csv(rej).empty and len(pd.read_csv(out)) == len(list(ann.rglob("*.bin")))


@pytest.mark.parametrize("command", ["convert", "audit"])
def test_convert_and_audit_set_damaged_pose_files_aside(tmp_path, command):
    """A damaged pose file in a BIWI folder is one reject naming the file (convert and audit read on past it);
    without --rejects the run stops at that file with one line and writes nothing."""
    ann, frames = _damaged_copy(tmp_path)
    out, rej = tmp_path / "o.parquet", tmp_path / "rej.csv"
    args = ["convert", str(ann), "-o", str(out), "--to", "300w_lp"] if command == "convert" else ["audit", str(ann)]
    r = hpe(*args, "-q")
    assert r.exit_code == 1 and len(r.output.strip().splitlines()) == 1, r.output
    assert "01/frame_00006_pose.bin: expected 24 bytes (6 float32), got 10" in r.output and not out.exists()
    r = hpe(*args, "--rejects", rej, "-q")
    assert r.exit_code == 0, r.output
    rejects = pd.read_csv(rej)
    assert sorted(rejects["raw"]) == ["01/frame_00006_pose.bin", "02/frame_00348_pose.bin", "03/frame_00562_pose.bin"]
    assert rejects.set_index("raw").loc["03/frame_00562_pose.bin", "reason"].startswith("yaw: expected degrees")
    if command == "convert":  # every frame is in the labels or in the rejects
        labels = pd.read_parquet(out)
        assert len(labels) + len(rejects) == len(frames)
        assert not set(labels["file"]) & set(rejects["raw"])
