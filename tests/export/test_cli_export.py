"""``hpe export`` through click: help, usage errors, bad input, staging, merged inputs."""

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import REALDATA, hpe

AFLW = REALDATA / "aflw2000_prnet"


def make_set(tmp_path, n_images=3, heads=2, size=(120, 160)):
    """A tiny table: n_images 160x120 images with ``heads`` boxes each, labels in 300w_lp degrees."""
    rng = np.random.default_rng(1)
    rows = []
    (tmp_path / "img").mkdir(exist_ok=True)
    for i in range(n_images):
        img = rng.integers(0, 255, size + (3,), dtype=np.uint8)
        cv2.imwrite(str(tmp_path / "img" / f"f{i}.jpg"), img)
        for h in range(heads):
            rows.append(
                {
                    "image": f"img/f{i}.jpg",
                    "sequence": f"s{i % 2}",
                    "camera": "",
                    "frame": i,
                    "person_id": h,
                    "bbox_x": 10 + 60 * h,
                    "bbox_y": 20,
                    "bbox_w": 40,
                    "bbox_h": 50,
                    "pitch": 10.0 * h,
                    "yaw": 20.0 * i - 30,
                    "roll": 5.0,
                }
            )
    path = tmp_path / "labels.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    return path


def test_help_has_examples():
    r = hpe("export", "--help")
    assert r.exit_code == 0 and "Examples:" in r.output and "--layout" in r.output


def test_usage_errors(tmp_path):
    path = make_set(tmp_path)
    r = hpe("export", path, "-o", tmp_path / "o", "--layout", "whenet", "--system", "6drepnet")
    assert r.exit_code == 2 and "whenet system" in r.output
    r = hpe("export", path, "-o", tmp_path / "o", "--layout", "whenet", "--form", "mat")
    assert r.exit_code == 2
    r = hpe("export", path, "-o", tmp_path / "o", "--layout", "nope")
    assert r.exit_code == 2
    assert not (tmp_path / "o").exists()


def test_existing_output_needs_overwrite(tmp_path):
    path = make_set(tmp_path)
    out = tmp_path / "o"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    r = hpe("export", path, "-o", out, "--layout", "whenet")
    assert r.exit_code == 1 and "already exists" in r.output and (out / "keep.txt").exists()
    r = hpe("export", path, "-o", out, "--layout", "whenet", "--overwrite", "-q")
    assert r.exit_code == 0, r.output
    assert not (out / "keep.txt").exists() and (out / "train" / "annotation.txt").is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging left behind


def test_bad_images_are_rejects(tmp_path):
    path = make_set(tmp_path, n_images=4)
    (tmp_path / "img" / "f1.jpg").unlink()  # missing
    (tmp_path / "img" / "f2.jpg").write_bytes(b"not a jpeg at all")  # unreadable
    t = pd.read_csv(path)
    t.loc[len(t)] = t.iloc[0]
    t.loc[len(t) - 1, ["bbox_x", "person_id"]] = [500, 9]  # outside the 160-px frame
    t.loc[len(t)] = t.iloc[0]
    t.loc[len(t) - 1, ["bbox_w", "person_id"]] = [np.nan, 8]  # no box
    t = t.astype({"pitch": object})
    t.loc[len(t)] = t.iloc[0]
    t.loc[len(t) - 1, ["pitch", "person_id"]] = ["abc", 7]  # not a number
    t.to_csv(path, index=False)
    with open(path, "a") as fh:
        fh.write("img/f0.jpg,s0,,0,5,1,2,3,4,5,6,7,8,9\n")  # too many fields
    out = tmp_path / "o"
    r = hpe("export", path, "-o", out, "--layout", "whenet", "--rejects", tmp_path / "rej.csv")
    assert r.exit_code == 0, r.output
    rej = pd.read_csv(tmp_path / "rej.csv")
    reasons = rej.set_index("row")["reason"].to_dict()
    # CSV rows are file lines: header = line 1
    assert reasons[4] == reasons[5] == "no image (file not found)"
    assert reasons[6] == reasons[7] == "unreadable image"
    assert reasons[10].startswith("box outside the image")
    assert reasons[11] == "missing or empty head box"
    assert "pitch" in reasons[12] and reasons[13].startswith("unreadable row")
    lines = (out / "train" / "annotation.txt").read_text().splitlines()
    assert len(lines) + len(rej) == len(t) + 1
    assert "rejected 8" in r.output and "unreadable image" in r.output
    # without --rejects, bad input is an error and nothing is written
    r = hpe("export", path, "-o", tmp_path / "o2", "--layout", "whenet")
    assert r.exit_code == 1 and "line 4: no image (file not found)" in r.output and "--rejects" in r.output
    assert not (tmp_path / "o2").exists()


def test_everything_rejected_writes_nothing(tmp_path):
    path = make_set(tmp_path)
    t = pd.read_csv(path)
    t["roll"] = 120.0  # |roll| >= 90 in every solution WHENet could keep
    t["pitch"] = 0.0
    t["yaw"] = 0.0
    t.to_csv(path, index=False)
    r = hpe("export", path, "-o", tmp_path / "o", "--layout", "whenet", "--rejects", tmp_path / "r.csv")
    assert r.exit_code == 1 and "every label is rejected" in r.output and "Traceback" not in r.output
    # the rejects file the user asked for is still written (every label, its reason); the export is not
    assert not (tmp_path / "o").exists() and len(pd.read_csv(tmp_path / "r.csv")) == len(t)
    for p in (tmp_path / "img",):
        (p / "f0.jpg").unlink()
    r = hpe("export", path, "-o", tmp_path / "o", "--layout", "hf", "--rejects", tmp_path / "r2.csv")
    assert r.exit_code == 0  # hf keeps any rotation: only the missing image is rejected
    r = hpe("export", path, "-o", tmp_path / "o3", "--layout", "hf", "--rejects", tmp_path / "r3.csv", "--strict")
    assert r.exit_code == 1 and "--strict" in r.output and not (tmp_path / "o3").exists()


def test_bad_table_is_one_line(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("a,b\n1,2\n")
    r = hpe("export", p, "-o", tmp_path / "o", "--layout", "whenet")
    assert r.exit_code == 1 and "expected columns image" in r.output and len(r.output.strip().splitlines()) == 1


def test_split_file_and_min_change_and_balance(tmp_path):
    path = make_set(tmp_path, n_images=6, heads=1)
    sf = tmp_path / "split.csv"
    sf.write_text("sequence,split\ns0,train\ns1,test\n")
    out = tmp_path / "o"
    r = hpe("export", path, "-o", out, "--layout", "hf", "--split-file", sf, "-q")
    assert r.exit_code == 0, r.output
    s = json.loads((out / "export.json").read_text())
    assert s["per_split"] == {"test": 3, "train": 3}
    sf.write_text("sequence,split\ns0,train\n")
    r = hpe(
        "export",
        path,
        "-o",
        out,
        "--layout",
        "hf",
        "--split-file",
        sf,
        "--overwrite",
        "--rejects",
        tmp_path / "r.csv",
        "-q",
    )
    assert r.exit_code == 0
    assert (pd.read_csv(tmp_path / "r.csv")["reason"] == "sequence not listed in --split-file").sum() == 3
    # balance: yaws -30,-10,10,30,50,70 in 40-degree bins from -180: [-60,-20) [-20,20) [20,60) [60,100),
    # at most 1 each -> 4
    r = hpe("export", path, "-o", out, "--layout", "hf", "--balance", "yaw:40:1", "--overwrite", "-q")
    assert r.exit_code == 0, r.output
    assert json.loads((out / "export.json").read_text())["exported"] == 4


@pytest.mark.skipif(not AFLW.exists(), reason="no AFLW2000 sample")
def test_merged_inputs_and_identity_split(tmp_path):
    path = make_set(tmp_path)
    out = tmp_path / "o"
    r = hpe(
        "export",
        AFLW,
        path,
        "-o",
        out,
        "--layout",
        "fsanet",
        "--images",
        AFLW,
        "--images",
        tmp_path,
        "--split",
        "identity:0.5,0.5",
        "-q",
    )
    assert r.exit_code == 0, r.output
    crops = pd.read_csv(out / "crops.csv")
    assert set(crops["source"]) == {"aflw2000_prnet", "labels"}
    n = sum(np.load(out / f"{s}.npz")["pose"].shape[0] for s in crops["split"].unique())
    assert n == len(crops) == 16 + 6


def test_agora_table(tmp_path):
    fixture = Path(__file__).resolve().parents[1] / "data" / "agora" / "validation_0_withjv.pkl"
    table = tmp_path / "agora.parquet"
    assert hpe("relabel-agora", fixture, "-o", table, "-q").exit_code == 0
    t = pd.read_parquet(table)
    for name in t["image"].unique():
        (tmp_path / "imgs" / name).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(tmp_path / "imgs" / name), np.full((2160, 3840, 3), 90, np.uint8))
    out = tmp_path / "o"
    r = hpe("export", table, "-o", out, "--layout", "hf", "--images", tmp_path / "imgs", "-q")
    assert r.exit_code == 0, r.output
    assert "AGORA" in (out / "README.md").read_text()
    assert json.loads((out / "export.json").read_text())["exported"] == len(t)


def test_video_source_through_panoptic_video(tmp_path, monkeypatch):
    """Panoptic rows without hdImgs read hdVideos/hd_<cam>.mp4 through pan's VideoFrames (a stand-in here)."""
    import sys
    import types

    from hpe_cli.pipelines.export import ExportOptions, run_export

    calls = []

    class VideoFrames:
        def __init__(self, path):
            self.path = path

        def read(self, frames):
            calls.append((Path(self.path).name, list(frames)))
            for f in frames:
                if f == 13:
                    yield f, None, "past the end of the video"
                else:
                    yield f, np.full((120, 160, 3), f, np.uint8), ""

    mod = types.ModuleType("hpe_cli.datasets.panoptic_video")
    mod.VideoFrames = VideoFrames
    monkeypatch.setitem(sys.modules, "hpe_cli.datasets.panoptic_video", mod)
    rows = [
        {
            "image": f"hdImgs/00_03/00_03_{f:08d}.jpg",
            "sequence": "seqA",
            "camera": "00_03",
            "frame": f,
            "person_id": 1,
            "bbox_x": 10.0,
            "bbox_y": 10.0,
            "bbox_w": 40.0,
            "bbox_h": 40.0,
            "pitch": 0.0,
            "yaw": 5.0 * f,
            "roll": 0.0,
        }
        for f in (12, 11, 13)
    ]
    path = tmp_path / "t.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    (tmp_path / "hdVideos").mkdir()
    (tmp_path / "hdVideos" / "hd_00_03.mp4").write_bytes(b"")
    s = run_export([path], tmp_path / "o", ExportOptions(layout="whenet", rejects=str(tmp_path / "r.csv")))
    assert calls == [("hd_00_03.mp4", [11, 12, 13])]  # one video, frames ascending, decoded once
    assert s["exported"] == 2
    rej = pd.read_csv(tmp_path / "r.csv")
    assert rej["reason"].tolist() == [
        "no image (video " + str(tmp_path / "hdVideos" / "hd_00_03.mp4") + " frame 13: past the end of the video)"
    ]
    crop = cv2.imread(str(tmp_path / "o" / "train" / "seqA" / "00_03_1_00000011.jpg"))
    assert crop.shape == (40, 40, 3) and abs(float(crop.mean()) - 11) < 2


def test_video_source_real_reader(tmp_path):
    """End to end with pan's VideoFrames on a small synthetic hdVideos/hd_00_05.mp4 (frame k is gray 40 k)."""
    pytest.importorskip("hpe_cli.datasets.panoptic_video")
    (tmp_path / "hdVideos").mkdir()
    vw = cv2.VideoWriter(str(tmp_path / "hdVideos" / "hd_00_05.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 30, (160, 120))
    if not vw.isOpened():
        pytest.skip("OpenCV cannot write mp4 here")
    for k in range(5):
        vw.write(np.full((120, 160, 3), 40 * k, np.uint8))
    vw.release()
    rows = [
        {
            "image": f"hdImgs/00_05/00_05_{f:08d}.jpg",
            "sequence": "",
            "camera": "00_05",
            "frame": f,
            "person_id": 0,
            "bbox_x": 20.0,
            "bbox_y": 20.0,
            "bbox_w": 50.0,
            "bbox_h": 50.0,
            "pitch": 0.0,
            "yaw": 10.0 * f,
            "roll": 0.0,
        }
        for f in (3, 1, 9)
    ]
    path = tmp_path / "t.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    r = hpe("export", path, "-o", tmp_path / "o", "--layout", "whenet", "--rejects", tmp_path / "r.csv")
    assert r.exit_code == 0, r.output
    for f in (1, 3):
        crop = cv2.imread(str(tmp_path / "o" / "train" / f"00_05_0_{f:08d}.jpg"))
        assert abs(float(crop.mean()) - 40 * f) < 6
    rej = pd.read_csv(tmp_path / "r.csv")
    assert len(rej) == 1 and "past the end" in rej["reason"].iloc[0]
    # pixel layouts get a video's crops through the worker's spill file
    r = hpe(
        "export", path, "-o", tmp_path / "f", "--layout", "fsanet", "--rejects", tmp_path / "r2.csv", "--workers", "2"
    )
    assert r.exit_code == 0, r.output
    d = np.load(tmp_path / "f" / "train.npz")
    assert d["image"].shape == (2, 64, 64, 3)
    np.testing.assert_allclose(d["image"].reshape(2, -1).mean(1), [40, 120], atol=6)
    assert not list((tmp_path / "f").glob(".spill-*"))


@pytest.mark.skipif(not (REALDATA / "300wlp_face3d").exists(), reason="no 300W-LP sample")
def test_w300lp_root_identity_groups(tmp_path):
    import shutil

    import scipy.io

    src = REALDATA / "300wlp_face3d" / "IBUG_image_008_1_0"
    root = tmp_path / "300W_LP"
    for sub, k in (("IBUG", 0), ("IBUG", 1), ("IBUG_Flip", 0)):
        (root / sub).mkdir(parents=True, exist_ok=True)
        for ext in (".jpg", ".mat"):
            shutil.copy(str(src) + ext, root / sub / f"IBUG_image_008_1_{k}{ext}")
    (root / "AFW").mkdir()
    for ext in (".jpg", ".mat"):
        shutil.copy(str(src) + ext, root / "AFW" / f"AFW_111_2_0{ext}")
    out = tmp_path / "o"
    r = hpe("export", root, "-o", out, "--layout", "6drepnet", "--form", "mat", "--split", "identity:0.5,0.5")
    assert r.exit_code == 0, r.output
    crops = pd.read_csv(out / "crops.csv")
    assert len(crops) == 4
    by_id = crops.assign(identity=crops["image"].str.extract(r"/(.+)_\d+\.jpg$")[0]).groupby("identity")["split"]
    assert (by_id.nunique() == 1).all() and set(by_id.groups) == {"IBUG_image_008_1", "AFW_111_2"}
    pose = scipy.io.loadmat(src.with_suffix(".mat"))["Pose_Para"][0][:3]
    for f in (out / crops["split"].iloc[0]).glob("*.mat"):
        np.testing.assert_allclose(scipy.io.loadmat(f)["Pose_Para"][0][:3], pose, atol=1e-6)


def test_radians_table_exports_the_same_rotations(tmp_path):
    """--radians: a table with its angles in radians exports the same rotations (as matrices) as in degrees."""
    from scipy.spatial.transform import Rotation

    deg = make_set(tmp_path, n_images=4, heads=2)
    t = pd.read_csv(deg)
    t["pitch"] += [0, -40, 70, 15, -85, 30, 5, -60]  # spread the angles over the range
    t["roll"] += [160, -120, 0, 45, -10, 90, -170, 20]
    t.to_csv(deg, index=False)
    rad = tmp_path / "labels_rad.csv"
    t.assign(**{c: np.radians(t[c]) for c in ("pitch", "yaw", "roll")}).to_csv(rad, index=False)
    got = {}
    for name, args in (("deg", [deg]), ("rad", [rad, "--radians"]), ("rad_as_deg", [rad])):
        out = tmp_path / name
        r = hpe("export", *args, "-o", out, "--layout", "hf", "--from", "300w_lp", "-q")
        assert r.exit_code == 0, r.output
        f = pd.concat([pd.read_parquet(p) for p in sorted(out.rglob("*.parquet"))], ignore_index=True)
        f = f.sort_values(["image_file", "person_id"], ignore_index=True)
        got[name] = np.stack([np.stack(m) for m in f["rotation"]]).astype(np.float64)
        if name == "rad_as_deg":
            assert "radians" in r.stderr  # the units watch: every |angle| is below pi
    # oracle: img2pose's 300W-LP reading (utils/json_loader_300wlp.py, SciPy "xyz" of pitch, -yaw, -roll),
    # transposed and seen in the camera frame diag(1, -1, -1)
    F = np.diag([1.0, -1.0, -1.0])
    pyr = t.sort_values(["image", "person_id"])[["pitch", "yaw", "roll"]].to_numpy()
    want = F @ Rotation.from_euler("xyz", pyr * [1, -1, -1], degrees=True).as_matrix().transpose(0, 2, 1) @ F
    assert got["deg"].shape == got["rad"].shape == (len(t), 3, 3)
    np.testing.assert_allclose(got["deg"], want, atol=1e-6)
    np.testing.assert_allclose(got["rad"], got["deg"], atol=1e-6)
    assert np.abs(got["rad_as_deg"] - got["deg"]).max() > 0.1  # without --radians the rotations differ
