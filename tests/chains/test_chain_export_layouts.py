"""Every export layout read by a reader transcribed from its trainer's CURRENT loading code, on the real samples.

Inputs: AFLW2000-3D (16 ``.mat`` + ``.jpg``) and 300W-LP (one) from ``shared/realdata``, and the CMU Panoptic
pizza1 sample relabelled by ``hpe relabel-panoptic``. Oracles, all independent of hpe's rotation code:

- the input rotation: ``Pose_Para[0][:3]`` read with ``scipy.io.loadmat`` (the ``.mat`` inputs) or the table's
  ``pitch, yaw, roll`` in the 300w_lp system (its ``hpe:system`` metadata); 6DRepNet's ``get_R(x, y, z) =
  Rz(z) Ry(y) Rx(x)`` (thohemp/6DRepNet@464b2ba5 sixdrepnet/utils.py:192-220) written with SciPy's
  ``Rotation.from_euler("ZYX", [z, y, x])``;
- the trainers' loaders, transcribed below with their ``repo@commit file:lines``;
- pixels: each landmark's neighbourhood in the exported image equals the same neighbourhood in the source
  image (same face pixels), and landmarks fall inside the image the trainer reads.

Each export is moved to another folder before it is read (a moved export must still load).
"""

from __future__ import annotations

import glob
import json
import os
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import scipy.io
from scipy.spatial.transform import Rotation

from conftest import REALDATA, hpe

from .conftest import PIZZA, geodesic_deg

AFLW = REALDATA / "aflw2000_prnet"
W300 = REALDATA / "300wlp_face3d"
pytestmark = pytest.mark.skipif(
    not (PIZZA.exists() and AFLW.exists() and W300.exists()), reason="shared/realdata is not available"
)
CAMS = "00_00,00_08,00_15,00_23"  # the pizza1 cameras with JPEGs in the sample


def get_R(x, y, z):
    """6DRepNet ``utils.get_R`` (Rz @ Ry @ Rx of radians), through SciPy."""
    return Rotation.from_euler("ZYX", [z, y, x]).as_matrix()


# ------------------------------------------------------------------------------------------------ inputs
@pytest.fixture(scope="module")
def pizza(tmp_path_factory):
    out = tmp_path_factory.mktemp("pizza") / "pizza.parquet"
    r = hpe("relabel-panoptic", PIZZA, "-o", out, "--cameras", CAMS, "-q")
    assert r.exit_code == 0, r.output
    return out, pd.read_parquet(out)


def mat_truth():
    """``stem -> (get_R of Pose_Para, visible pt2d (K, 2), source image path)`` for the .mat inputs."""
    out = {}
    for d in (AFLW, W300):
        for m in sorted(d.glob("*.mat")):
            mat = scipy.io.loadmat(m)
            p, y, r = mat["Pose_Para"][0][:3].astype(np.float64)
            pts = mat["pt2d"].T.astype(np.float64)
            pts = pts[(pts != -1).all(1)]
            out[m.stem] = (get_R(p, y, r), pts, m.with_suffix(".jpg"))
    return out


def pizza_truth(t):
    """``(camera, person, frame) -> (get_R of the table's 300w_lp angles, landmarks, source image)``."""
    n_lm = sum(1 for c in t.columns if re.fullmatch(r"lm\d+_x", c))
    out = {}
    for row in t.itertuples():
        pts = np.array([[getattr(row, f"lm{i}_x"), getattr(row, f"lm{i}_y")] for i in range(n_lm)])
        pts = pts[np.isfinite(pts).all(1)]
        src = PIZZA / "hdImgs" / f"hd_{row.camera}" / f"{int(row.frame):08d}.jpg"  # this copy's layout
        out[(row.camera, int(row.person_id), int(row.frame))] = (
            get_R(*np.deg2rad([row.pitch, row.yaw, row.roll])),
            pts,
            src,
        )
    return out


def truth_of(name, truth):
    stem = Path(name).stem
    m = re.fullmatch(r"(\d\d_\d\d)_(\d+)_(\d{8})", stem)
    return truth[(m.group(1), int(m.group(2)), int(m.group(3)))] if m else truth[stem]


@pytest.fixture(scope="module")
def truth(pizza):
    return {**mat_truth(), **pizza_truth(pizza[1])}


def export(tmp_path, inputs, *args):
    """Run ``hpe export`` with ``--rejects``, check labels + rejects = input rows, move the export, return it."""
    out, rej = tmp_path / "out", tmp_path / "rej.csv"
    r = hpe("export", *inputs, "-o", out, "--rejects", rej, "-q", *args)
    assert r.exit_code == 0, r.output
    summary = json.loads((out / "export.json").read_text())
    rejects = pd.read_csv(rej) if rej.stat().st_size else pd.DataFrame(columns=["reason"])
    assert summary["exported"] + len(rejects) == summary["labels"]
    assert summary["read_by"]  # the trainer code that reads it, repo@commit file:lines
    moved = tmp_path / "moved" / "elsewhere"
    moved.parent.mkdir()
    shutil.move(str(out), str(moved))
    assert not out.exists()
    return moved, summary, rejects


def same_pixels(src_img, src_pts, dst_img, dst_pts, half=4, tol=14.0):
    """Mean absolute grey difference of (2 half + 1)^2 patches around each point pair fully inside both images."""
    a = cv2.cvtColor(src_img, cv2.COLOR_BGR2GRAY).astype(np.float64)
    b = cv2.cvtColor(dst_img, cv2.COLOR_BGR2GRAY).astype(np.float64)
    diffs = []
    for (xs, ys), (xd, yd) in zip(np.round(src_pts).astype(int), np.round(dst_pts).astype(int)):
        if (
            half <= xs < a.shape[1] - half
            and half <= ys < a.shape[0] - half
            and half <= xd < b.shape[1] - half
            and half <= yd < b.shape[0] - half
        ):
            pa = a[ys - half : ys + half + 1, xs - half : xs + half + 1]
            pb = b[yd - half : yd + half + 1, xd - half : xd + half + 1]
            diffs.append(np.abs(pa - pb).mean())
    assert diffs, "no landmark inside both images"
    assert float(np.median(diffs)) < tol, diffs


# ------------------------------------------------------------------------------- 6drepnet, --form mat
def read_sixdrepnet_mat(data_dir, filename_path, hopenet=False):
    """thohemp/6DRepNet@464b2ba5 sixdrepnet/datasets.py:15-21 (get_list_from_filenames) and :37-72 (AFLW2000
    __getitem__; Pose_300W_LP :244-293 reads the same keys), 6DRepNet360@b06e4fed the same lines;
    natanielruiz/deep-head-pose@f7bbb998 code/datasets.py:95-136 (Hopenet: degrees and 66 bins)."""
    with open(filename_path) as f:
        lines = f.read().splitlines()
    for stem in lines:
        img = cv2.imread(os.path.join(data_dir, stem + ".jpg"))
        mat = scipy.io.loadmat(os.path.join(data_dir, stem + ".mat"))
        pt2d = mat["pt2d"]
        x_min, y_min, x_max, y_max = min(pt2d[0, :]), min(pt2d[1, :]), max(pt2d[0, :]), max(pt2d[1, :])
        k = 0.20
        x_min -= 2 * k * abs(x_max - x_min)
        y_min -= 2 * k * abs(y_max - y_min)
        x_max += 2 * k * abs(x_max - x_min)
        y_max += 0.6 * k * abs(y_max - y_min)
        box = (int(x_min), int(y_min), int(x_max), int(y_max))
        pitch, yaw, roll = mat["Pose_Para"][0][:3]
        out = {"stem": stem, "img": img, "pt2d": pt2d.T, "box": box, "R": get_R(pitch, yaw, roll)}
        if hopenet:
            deg = np.array([yaw, pitch, roll]) * 180 / np.pi
            out["bins"] = np.digitize(deg, np.array(range(-99, 102, 3))) - 1
        yield out


def check_mat_items(items, truth, src_cache):
    n = 0
    for it in items:
        R_in, pts_in, src = truth_of(it["stem"], truth)
        assert geodesic_deg(it["R"], R_in) < 1e-6
        h, w = it["img"].shape[:2]
        x0, y0, x1, y1 = it["box"]
        assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h  # the loader's loose crop lies inside the written image
        pts = it["pt2d"]
        assert len(pts) == len(pts_in) and (pts >= 0).all() and (pts[:, 0] < w).all() and (pts[:, 1] < h).all()
        # the same face pixels: the crop is a shift of the source (no resize in the .mat form)
        off = pts_in - pts
        np.testing.assert_allclose(off, off[:1].repeat(len(off), 0), atol=1e-6)
        if src not in src_cache:
            src_cache[src] = cv2.imread(str(src))
        src_img = src_cache[src]
        same_pixels(src_img, pts_in, it["img"], pts)
        n += 1
    return n


@pytest.mark.parametrize("trainer", [None, "hopenet", "6drepnet360"])
def test_6drepnet_mat_read_by_its_loaders(tmp_path, pizza, truth, trainer):
    args = ["--trainer", trainer] if trainer else []
    out, summary, rej = export(
        tmp_path,
        [AFLW, W300, pizza[0]],
        "--layout",
        "6drepnet",
        "--images",
        AFLW,
        "--images",
        W300,
        "--images",
        PIZZA,
        *args,
    )
    assert summary["form"] == "mat" and summary["trainer"] == (trainer or "6drepnet")
    items = list(read_sixdrepnet_mat(out / "train", out / "train" / "files.txt", hopenet=trainer == "hopenet"))
    assert check_mat_items(items, truth, {}) == summary["exported"] > 17
    listed = {Path(it["stem"]).name for it in items}
    assert {m.stem for m in AFLW.glob("*.mat")} | {"IBUG_image_008_1_0"} <= listed
    ang = {it["stem"]: np.degrees(Rotation.from_matrix(it["R"]).as_euler("ZYX")[::-1]) for it in items}
    if trainer == "hopenet":  # every listed label has one of Hopenet's 66 classes
        assert all(((it["bins"] >= 0) & (it["bins"] <= 65)).all() for it in items)
    reasons = rej["reason"].astype(str)
    if trainer == "6drepnet360":  # full range: no label is dropped for its angles
        assert not reasons.str.contains("99").any()
        assert any(np.abs(a).max() > 99 for a in ang.values())
    else:
        assert reasons.str.contains("Hopenet bins" if trainer else "create_filename_list").sum() > 0


# ------------------------------------------------------------------------------- 6drepnet, --form crops
def read_pose_agora_cmu(data_dir, filename_path):
    """hnuzhy/DirectMHP@a51b06bc exps/sixdrepnet.zip:sixdrepnet/datasets.py:307-351 (Pose_AGORA_CMU)."""
    with open(filename_path) as f:
        lines = f.read().splitlines()
    for line in lines:
        line = line.strip()
        [filename, pitch, yaw, roll] = line.split(" ")
        path = os.path.join(data_dir, filename)
        p, y, r = (float(v) * np.pi / 180 for v in (pitch, yaw, roll))
        yield filename, cv2.imread(path), get_R(p, y, r)


def test_6drepnet_crops_read_by_directmhp_fork(tmp_path, pizza, truth):
    out, summary, _ = export(tmp_path, [pizza[0]], "--layout", "6drepnet", "--form", "crops", "--images", PIZZA)
    items = list(read_pose_agora_cmu(out / "train", out / "files_train.txt"))
    assert len(items) == summary["exported"] > 0
    for name, img, R in items:
        assert img.shape == (256, 256, 3)
        assert geodesic_deg(R, truth_of(name, truth)[0]) < 1e-6


# ------------------------------------------------------------------------------------------- directmhp
IMG_FORMATS = ["bmp", "jpg", "jpeg", "png", "tif", "tiff", "dng", "webp", "mpo"]


def _safe_load(text):
    try:
        import yaml

        return yaml.safe_load(text)
    except ImportError:  # the file is flat "key: value" lines
        out = {}
        for line in text.splitlines():
            if line.strip() and not line.startswith("#") and ":" in line:
                k, v = line.split(":", 1)
                out[k.strip()] = v.strip()
        return out


def directmhp_load(yaml_file, task):
    """hnuzhy/DirectMHP@a51b06bc: utils/general.py:277-285 (check_dataset: yaml.safe_load, ``path`` joined to each
    split entry), utils/datasets.py:394-407 (a folder entry is globbed), :371-372 (img2label_paths), :909-925
    (label lines, ``(l >= 0).all()``), val.py:177 (the COCO file of ``<task>_annotations``), val.py:181 (the image
    id is the file stem)."""
    with open(yaml_file, errors="ignore") as f:
        data = _safe_load(f.read())
    path = Path(data.get("path") or "")
    for k in "train", "val", "test":
        if data.get(k):
            data[k] = str(path / data[k])
    p = Path(data[task])
    if p.is_dir():
        f = glob.glob(str(p / "**" / "*.*"), recursive=True)
    else:
        with open(p) as t:
            t = t.read().strip().splitlines()
            parent = str(p.parent) + os.sep
            f = [x.replace("./", parent) if x.startswith("./") else x for x in t]
    img_files = sorted([x.replace("/", os.sep) for x in f if x.split(".")[-1].lower() in IMG_FORMATS])
    assert img_files, "No images found"
    label_files = [os.path.splitext(s.replace("images", data["labels"]))[0] + ".txt" for s in img_files]
    labels = []
    for lb_file in label_files:
        with open(lb_file) as fh:
            lab = np.array([x.split() for x in fh.read().strip().splitlines() if len(x)], dtype=np.float32)
        assert (lab >= 0).all(), "negative labels"
        labels.append(lab)
    annot = os.path.join(data["path"], data[f"{task}_annotations"])
    with open(annot) as fh:
        coco = json.load(fh)
    img_ids = [int(Path(x).stem) for x in img_files]
    return img_files, labels, coco, img_ids


def test_directmhp_read_by_its_loader_after_a_move(tmp_path, pizza, truth, monkeypatch):
    out, summary, _ = export(
        tmp_path, [pizza[0]], "--layout", "directmhp", "--images", PIZZA, "--split", "camera:train=0.75,val=0.25"
    )
    monkeypatch.chdir(out)  # path: . -- DirectMHP's check_dataset joins it to the working folder
    n = 0
    for task in ("train", "val"):
        img_files, labels, coco, img_ids = directmhp_load("data.yaml", task)
        assert sorted(im["id"] for im in coco["images"]) == sorted(img_ids)
        anns = {}
        for a in coco["annotations"]:
            anns.setdefault(a["image_id"], []).append(a)
        for f, lab, i in zip(img_files, labels, img_ids):
            img = cv2.imread(f)
            H, W = img.shape[:2]
            assert len(lab) == len(anns[i])
            node, frame = i % 100, (i // 100) % 1_000_000
            for line, a in zip(lab, anns[i]):
                x, y, w, h = a["bbox"]
                np.testing.assert_allclose(line[1:5], [(x + w / 2) / W, (y + h / 2) / H, w / W, h / H], atol=1e-6)
                p, yw, r = (line[5] - 0.5) * 180, (line[6] - 0.5) * 360, (line[7] - 0.5) * 180
                np.testing.assert_allclose([p, yw, r], a["euler_angles"], atol=2e-4)
                R = get_R(*np.deg2rad(a["euler_angles"]))
                cands = [
                    v
                    for key, v in truth.items()
                    if isinstance(key, tuple) and key[0] == f"00_{node:02d}" and key[2] == frame
                ]
                assert min(geodesic_deg(R, v[0]) for v in cands) < 1e-6
                pts = np.array(a["face2d_pts"], dtype=float).T
                vis = (pts != -1).all(1)
                assert ((pts[vis] >= 0) & (pts[vis] < [W, H])).all()
                n += 1
    assert n == summary["exported"] > 0


# ---------------------------------------------------------------------------------------------- fsanet
def test_fsanet_read_by_fsanet_and_6drepnet_biwi(tmp_path, pizza, truth):
    out, summary, _ = export(tmp_path, [AFLW, W300], "--layout", "fsanet", "--images", AFLW, "--images", W300)
    # shamangary/FSA-Net@4361d0e4 training_and_testing/FSANET_fine_train.py:25-27, :78-87
    d = np.load(out / "train.npz")
    image, pose = d["image"], d["pose"]
    keep = [i for i in range(pose.shape[0]) if np.max(pose[i, :]) <= 99.0 and np.min(pose[i, :]) >= -99.0]
    assert len(keep) == len(pose) == summary["exported"] == 17 and image.shape[1:] == (64, 64, 3)
    crops = pd.read_csv(out / "crops.csv")
    for k in range(len(pose)):
        # thohemp/6DRepNet@464b2ba5 sixdrepnet/datasets.py:196-214 (BIWI: yaw, pitch, roll degrees -> get_R)
        yaw, pitch, roll = pose[k] / 180 * np.pi
        R = get_R(pitch, yaw, roll)
        R_in, _, src = truth_of(crops["image"].iloc[k], truth)
        assert geodesic_deg(R, R_in) < 1e-6
        # the crop is the source's box, resized: compare at 64 x 64
        x0, y0, x1, y1 = crops[["crop_x0", "crop_y0", "crop_x1", "crop_y1"]].iloc[k]
        s = cv2.imread(str(src))
        pad = cv2.copyMakeBorder(s, 400, 400, 400, 400, cv2.BORDER_CONSTANT, value=0)
        ref = cv2.resize(pad[y0 + 400 : y1 + 400, x0 + 400 : x1 + 400], (64, 64), interpolation=cv2.INTER_AREA)
        assert np.abs(ref.astype(float) - image[k].astype(float)).mean() < 8  # BGR, as FSA-Net's cv2.imread


# -------------------------------------------------------------------------------------------------- hf
def read_hf_parquet(folder):
    """What ``datasets.load_dataset("parquet")`` gives: rows, with the ``huggingface`` schema features."""
    import pyarrow.parquet as pq

    rows = []
    for f in sorted(glob.glob(str(folder / "data" / "*.parquet"))):
        feats = json.loads(pq.read_schema(f).metadata[b"huggingface"])["info"]["features"]
        assert feats["image"] == {"_type": "Image"} and feats["rotation"]["_type"] == "Array2D"
        rows += pq.read_table(f).to_pylist()
    return rows


def test_hf_pose_dataset(tmp_path, pizza, truth):
    out, summary, _ = export(
        tmp_path, [AFLW, W300, pizza[0]], "--layout", "hf", "--images", AFLW, "--images", W300, "--images", PIZZA
    )
    card = (out / "README.md").read_text()
    head = card.split("---")[1]
    assert "image-classification" not in head and "keypoint-detection" in head and "pose-estimation" in head
    assert "array2_d" in head and "source_landmarks_x" in head
    rows = read_hf_parquet(out)
    assert len(rows) == summary["exported"] > 17
    cache = {}
    for row in rows:
        name = row["image"]["path"]
        R_in, _, src = truth_of(name, truth)
        R = np.array(row["rotation"], dtype=float)
        assert R.shape == (3, 3)
        assert geodesic_deg(R, R_in.T) < 1e-6  # 300w_lp: the stored matrix is get_R(angles) transposed
        assert geodesic_deg(get_R(*np.deg2rad([row["pitch"], row["yaw"], row["roll"]])), R_in) < 1e-6
        img = cv2.imdecode(np.frombuffer(row["image"]["bytes"], np.uint8), cv2.IMREAD_COLOR)
        src_pts = np.stack([row["source_landmarks_x"], row["source_landmarks_y"]], 1)
        crop_pts = np.stack([row["landmarks_x"], row["landmarks_y"]], 1)
        ok = np.isfinite(src_pts).all(1)
        assert ok.any()
        # the crop's landmarks lie inside the crop, on the same face pixels as the source ones
        inside = (crop_pts[ok] >= 0).all(1) & (crop_pts[ok] < [img.shape[1], img.shape[0]]).all(1)
        assert inside.mean() > 0.9
        if src not in cache:
            cache[src] = cv2.imread(str(src))
        same_pixels(cache[src], src_pts[ok], img, crop_pts[ok])
    try:
        import datasets
    except ImportError:
        return
    ds = datasets.load_dataset(str(out))
    assert sum(len(v) for v in ds.values()) == len(rows)
    assert np.array(ds["train"][0]["rotation"]).shape == (3, 3)


# ---------------------------------------------------------------------------------------------- whenet
def test_whenet_annotation_lines(tmp_path, pizza, truth):
    out, summary, _ = export(tmp_path, [pizza[0]], "--layout", "whenet", "--images", PIZZA)
    lines = (out / "train" / "annotation.txt").read_text().splitlines()
    assert len(lines) == summary["exported"] > 0
    for line in lines:
        path, yaw, pitch, roll = line.split(",")
        assert (out / "train" / path).is_file()
        R = get_R(*np.deg2rad([float(pitch), float(yaw), float(roll)]))
        assert geodesic_deg(R, truth_of(path, truth)[0]) < 1e-6
