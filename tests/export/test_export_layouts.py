"""Each export layout read back by a small reader written from its trainer's loading code.

Oracles: the trainers' own formulas written out here (6DRepNet ``utils.get_R``, DirectMHP's YOLO
normalisation and image-id scheme, FSA-Net's ``np.load`` keys), SPEC §2's 300W-LP matrix (``canonical_A``),
and physical consistency (the projected landmarks fall inside each crop).
"""

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import scipy.io

from conftest import REALDATA, canonical_A, hpe

PIZZA = REALDATA / "panoptic_160906_pizza1"
AFLW = REALDATA / "aflw2000_prnet"
pytestmark = pytest.mark.skipif(not PIZZA.exists(), reason="../shared/realdata is not available")


def export(path, out, *args):
    """``hpe export`` on the pizza table; its frames without a JPEG in the sample are rejects."""
    return hpe("export", path, "-o", out, "--images", PIZZA, "--rejects", Path(str(out) + "_rejects.csv"), *args)


@pytest.fixture(scope="module")
def pizza(tmp_path_factory):
    """relabel-panoptic on the real pizza1 sample, restricted to the 4 cameras with real images."""
    d = tmp_path_factory.mktemp("pizza")
    out = d / "pizza.parquet"
    r = hpe("relabel-panoptic", PIZZA, "-o", out, "--cameras", "00_00,00_08,00_15,00_23", "-q")
    assert r.exit_code == 0, r.output
    return out, pd.read_parquet(out)


def table_A(t):
    """The table's canonical matrices (the relabel table is in 300w_lp, whose stored matrix is A)."""
    return t[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)


def key_of_crop(name):
    """WHENet-style crop name <sequence>/<camera>_<person>_<frame>.jpg -> (camera, person, frame)."""
    stem = Path(name).stem
    cam0, cam1, person, frame = stem.split("_")
    return f"{cam0}_{cam1}", int(person), int(frame)


def lookup(t):
    return {(c, int(p), int(f)): k for k, (c, p, f) in enumerate(zip(t["camera"], t["person_id"], t["frame"]))}


def check_crop_holds_head(out_dir, t, split="train", tol=0.9, sized=False):
    """Physical check: the table's projected 2-D landmarks fall inside each recorded crop box."""
    crops = pd.read_csv(out_dir / "crops.csv")
    idx = lookup(t)
    n_lm = 70
    for _, c in crops[crops["split"] == split].iterrows():
        k = idx[key_of_crop(c["file"])]
        x = t[[f"lm{i}_x" for i in range(n_lm)]].iloc[k].to_numpy(float)
        y = t[[f"lm{i}_y" for i in range(n_lm)]].iloc[k].to_numpy(float)
        ok = np.isfinite(x) & np.isfinite(y)
        inside = (x >= c.crop_x0) & (x < c.crop_x1) & (y >= c.crop_y0) & (y < c.crop_y1)
        assert inside[ok].mean() >= tol
        img = cv2.imread(str(out_dir / split / c["file"]))
        assert img is not None and img.shape[1] == c.out_w and img.shape[0] == c.out_h
        if not sized:
            assert (c.out_w, c.out_h) == (c.crop_x1 - c.crop_x0, c.crop_y1 - c.crop_y0)


def get_R_6drepnet(pitch, yaw, roll):
    """6DRepNet ``sixdrepnet/utils.py::get_R`` as its docs describe it: R = Rz(roll) Ry(yaw) Rx(pitch), radians."""
    x, y, z = pitch, yaw, roll
    Rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


# --------------------------------------------------------------------------------------------- whenet
def test_whenet_layout_read_back(pizza, tmp_path):
    path, t = pizza
    out = tmp_path / "w"
    r = hpe(
        "export",
        path,
        "-o",
        out,
        "--layout",
        "whenet",
        "--images",
        PIZZA,
        "--rejects",
        tmp_path / "rej.csv",
        "--crop-scale",
        "1.2",
    )
    assert r.exit_code == 0, r.output
    # WHENet's reader: lines "relative/path.jpg,yaw,pitch,roll", paths relative to the dataset folder
    lines = (out / "train" / "annotation.txt").read_text().splitlines()
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert len(lines) + len(rej) == len(t)  # every label exported or rejected
    assert (rej["reason"].str.startswith("WHENet rule") | rej["reason"].str.startswith("no image")).all()
    idx = lookup(t)
    A = table_A(t)
    for line in lines:
        name, yaw, pitch, roll = line.split(",")
        assert (out / "train" / name).is_file()
        p, y, rr = float(pitch), float(yaw), float(roll)
        assert abs(p) < 90 and abs(rr) < 90
        k = idx[key_of_crop(name)]
        np.testing.assert_allclose(canonical_A([[p, y, rr]])[0], A[k], atol=1e-9)
    # the rejected WHENet-rule rows really cannot be written with |pitch|, |roll| < 90
    assert len(lines) > 0
    check_crop_holds_head(out, t)


def test_whenet_workers_give_the_same_files(pizza, tmp_path):
    path, t = pizza
    a, b = tmp_path / "a", tmp_path / "b"
    assert export(path, a, "--layout", "whenet", "-q").exit_code == 0
    assert export(path, b, "--layout", "whenet", "--workers", "2", "-q").exit_code == 0
    assert (a / "train" / "annotation.txt").read_text() == (b / "train" / "annotation.txt").read_text()
    for line in (a / "train" / "annotation.txt").read_text().splitlines()[:5]:
        name = line.split(",")[0]
        assert (a / "train" / name).read_bytes() == (b / "train" / name).read_bytes()


# --------------------------------------------------------------------------------------------- 6drepnet
def test_6drepnet_crops_matrices(pizza, tmp_path):
    path, t = pizza
    out = tmp_path / "s"
    assert export(path, out, "--layout", "6drepnet", "--form", "crops", "-q").exit_code == 0
    idx = lookup(t)
    A = table_A(t)
    # DirectMHP's gen_dataset_full_AGORA_CMU.py list: "<name>.jpg pitch yaw roll", 256 x 256 crops
    lines = (out / "files_train.txt").read_text().splitlines()
    assert lines
    for line in lines:
        name, p, y, r = line.split(" ")
        assert cv2.imread(str(out / "train" / name)).shape == (256, 256, 3)
        assert abs(float(p)) < 90 and abs(float(r)) < 90  # the whenet (COCO euler_angles) solution
        G = get_R_6drepnet(*np.deg2rad([float(p), float(y), float(r)]))
        np.testing.assert_allclose(G, A[idx[key_of_crop(name)]].T, atol=1e-9)  # 6DRepNet's matrix is A^T
    check_crop_holds_head(out, t, sized=True)


@pytest.mark.skipif(not AFLW.exists(), reason="no AFLW2000 sample")
def test_6drepnet_mat_form_on_aflw2000(tmp_path):
    out = tmp_path / "m"
    r = hpe("export", AFLW, "-o", out, "--layout", "6drepnet", "--form", "mat")
    assert r.exit_code == 0, r.output
    names = (out / "train" / "files.txt").read_text().splitlines()
    assert sorted(names) == sorted(p.stem for p in AFLW.glob("*.mat"))
    for name in names:
        # 6DRepNet's AFLW2000/Pose_300W_LP loaders: Pose_Para[0][:3] radians -> get_R; crop from pt2d min/max
        mat = scipy.io.loadmat(out / "train" / f"{name}.mat")
        pose = mat["Pose_Para"][0][:3]
        orig = scipy.io.loadmat(AFLW / f"{name}.mat")
        p0, y0, r0 = orig["Pose_Para"][0][:3].astype(float)
        np.testing.assert_allclose(get_R_6drepnet(*pose), canonical_A(np.rad2deg([[p0, y0, r0]]))[0].T, atol=1e-6)
        img = cv2.imread(str(out / "train" / f"{name}.jpg"))
        pt2d = mat["pt2d"]
        assert pt2d.shape[0] == 2 and (pt2d >= 0).all()
        x_min, y_min, x_max, y_max = pt2d[0].min(), pt2d[1].min(), pt2d[0].max(), pt2d[1].max()
        k = 0.20  # the AFLW2000 test loader's loose crop must lie inside the written image
        x_min -= 2 * k * abs(x_max - x_min)
        y_min -= 2 * k * abs(y_max - y_min)
        x_max += 2 * k * abs(x_max - x_min)
        y_max += 0.6 * k * abs(y_max - y_min)
        assert x_min >= 0 and y_min >= 0 and x_max <= img.shape[1] and y_max <= img.shape[0]
        # the landmarks moved with the crop: pixels around a landmark match the original image
        src = cv2.imread(str(AFLW / f"{name}.jpg"))
        vis = orig["pt2d"][:, (orig["pt2d"][0] != -1) & (orig["pt2d"][1] != -1)]
        np.testing.assert_allclose(pt2d - pt2d[:, :1], vis - vis[:, :1], atol=1e-9)
        dx, dy = np.round(pt2d[:, 0] - vis[:, 0]).astype(int)
        u, v = int(round(vis[0, 0])), int(round(vis[1, 0]))
        a = src[v - 3 : v + 4, u - 3 : u + 4].astype(float)
        b = img[v + dy - 3 : v + dy + 4, u + dx - 3 : u + dx + 4].astype(float)
        assert np.abs(a - b).mean() < 12


# --------------------------------------------------------------------------------------------- directmhp
def test_directmhp_layout(pizza, tmp_path):

    path, t = pizza
    out = tmp_path / "d"
    r = hpe(
        "export",
        path,
        "-o",
        out,
        "--layout",
        "directmhp",
        "--images",
        PIZZA,
        "--rejects",
        tmp_path / "r.csv",
        "--split",
        DMHP_SPLIT,
    )
    assert r.exit_code == 0, r.output
    A = table_A(t)
    idx = lookup(t)
    n_ann = 0
    for split in ("train", "val"):
        coco = json.loads((out / "annotations" / f"coco_style_{split}.json").read_text())
        assert {"images", "annotations", "categories"} <= set(coco)
        n_ann += len(coco["annotations"])
        _check_directmhp_split(out, split, coco, A, idx)
    assert "path: .\n" in (out / "data.yaml").read_text()  # no absolute path: the export can be moved
    rej = pd.read_csv(tmp_path / "r.csv")
    assert len(rej) + n_ann == len(t)


DMHP_SPLIT = "camera:train=0.75,val=0.25"


def _check_directmhp_split(out, split, coco, A, idx):
    from hpe_cli.io.export.directmhp import SEQ_NAMES

    for im in coco["images"]:
        i = im["id"]
        assert im["file_name"] == f"{i}.jpg" and (out / "images" / split / im["file_name"]).is_file()
        seq_num = (i - 10000000000) // 100000000 - 1  # data_split_hpe.py
        assert SEQ_NAMES[seq_num] == "160906_pizza1"
        frame, node = (i // 100) % 1_000_000, i % 100
        assert frame in (1147, 6577) and node in (0, 8, 15, 23)
        img = cv2.imread(str(out / "images" / split / im["file_name"]))
        assert img.shape[:2] == (im["height"], im["width"])
        # YOLO label lines: every value in [0, 1]; the angles decode back to the table's rotation
        lines = (out / "yolov5_labels_coco" / split / f"{i}.txt").read_text().splitlines()
        anns = [a for a in coco["annotations"] if a["image_id"] == i]
        assert len(lines) == len(anns)
        for line, a in zip(lines, anns):
            v = np.array([float(x) for x in line.split()])
            assert v[0] == 0 and (v >= 0).all() and (v <= 1).all()
            p, y, rr = (v[5] - 0.5) * 180, (v[6] - 0.5) * 360, (v[7] - 0.5) * 180
            np.testing.assert_allclose([p, y, rr], a["euler_angles"], atol=360 * 5e-7)  # 6 decimals
            Aw = canonical_A([a["euler_angles"]])[0]
            cands = [j for (c, pid, f), j in idx.items() if c == f"00_{node:02d}" and f == frame]
            assert min(np.abs(A[j] - Aw).max() for j in cands) < 1e-9


def test_directmhp_drop_images_with_rejects(pizza, tmp_path):
    _, t = pizza
    # one head of frame 1147 / camera 00_00 turned upside down: roll 170 cannot be normalised
    t = t.copy()
    k = int(np.flatnonzero((t["camera"] == "00_00").to_numpy() & (t["frame"] == 1147).to_numpy())[0])
    t.loc[k, ["pitch", "yaw", "roll"]] = [0.0, 0.0, 170.0]
    t.loc[k, [f"r{i}{j}" for i in range(3) for j in range(3)]] = canonical_A([[0.0, 0.0, 170.0]])[0].ravel()
    path = tmp_path / "t.parquet"
    t.to_parquet(path)
    out = tmp_path / "d"
    r = hpe(
        "export",
        path,
        "-o",
        out,
        "--layout",
        "directmhp",
        "--images",
        PIZZA,
        "--drop-images-with-rejects",
        "--rejects",
        tmp_path / "r.csv",
        "--split",
        DMHP_SPLIT,
    )
    assert r.exit_code == 0, r.output
    rej = pd.read_csv(tmp_path / "r.csv")
    coco = {
        "images": [
            im
            for s in ("train", "val")
            for im in json.loads((out / "annotations" / f"coco_style_{s}.json").read_text())["images"]
        ]
    }
    dropped = rej[rej["reason"].str.startswith("image dropped")]
    rule = rej[rej["reason"].str.startswith("DirectMHP normalisation")]
    # no exported image has a rejected (normalisation) head
    bad_images = set(rule["image"])
    assert len(dropped) > 0 and set(dropped["image"]) <= bad_images
    kept = {(im["id"] // 100) % 1_000_000 * 100 + im["id"] % 100 for im in coco["images"]}
    for img in bad_images:
        cam, fr = Path(img).stem.rsplit("_", 1)
        assert int(fr) * 100 + int(cam.split("_")[1]) not in kept


# --------------------------------------------------------------------------------------------- fsanet
def test_fsanet_npz(pizza, tmp_path):
    path, t = pizza
    out = tmp_path / "f"
    assert export(path, out, "--layout", "fsanet", "-q").exit_code == 0
    d = np.load(out / "train.npz")  # FSA-Net's loaders: np.load(path)['image'], ['pose']
    img, pose = d["image"], d["pose"]
    assert img.dtype == np.uint8 and img.shape[1:] == (64, 64, 3) and pose.shape == (img.shape[0], 3)
    assert int(d["img_size"]) == 64
    assert (np.abs(pose) <= 99).all()
    crops = pd.read_csv(out / "crops.csv")
    idx = lookup(t)
    A = table_A(t)
    for k, name in enumerate(crops["file"]):
        yaw, pitch, roll = pose[k]
        assert abs(yaw) <= 90
        np.testing.assert_allclose(canonical_A([[pitch, yaw, roll]])[0], A[idx[key_of_crop(name)]], atol=1e-9)
    # the array holds the crop: compare with a crop cut and resized from the source frame here
    c = crops.iloc[0]
    cam, person, frame = key_of_crop(c["file"])
    src = cv2.imread(str(PIZZA / "hdImgs" / f"hd_{cam}" / f"{frame:08d}.jpg"))
    x0, y0, x1, y1 = int(c.crop_x0), int(c.crop_y0), int(c.crop_x1), int(c.crop_y1)
    pad = cv2.copyMakeBorder(src, 500, 500, 500, 500, cv2.BORDER_CONSTANT, value=0)
    ref = cv2.resize(pad[y0 + 500 : y1 + 500, x0 + 500 : x1 + 500], (64, 64), interpolation=cv2.INTER_AREA)
    assert np.abs(ref.astype(float) - img[0].astype(float)).mean() < 1.0


# --------------------------------------------------------------------------------------------- hf
def test_hf_parquet_image_feature(pizza, tmp_path):
    import pyarrow.parquet as pq

    path, t = pizza
    out = tmp_path / "h"
    r = export(
        path, out, "--layout", "hf", "--system", "6drepnet", "--split", "camera:0.5,0.5", "--min-change", "1", "-q"
    )
    assert r.exit_code == 0, r.output
    card = (out / "README.md").read_text()
    assert card.startswith("---\n") and "dtype: image" in card and "6drepnet" in card and "min-change" in card
    idx = lookup(t)
    A = table_A(t)
    total = 0
    cams = {}
    for f in sorted((out / "data").glob("*.parquet")):
        meta = json.loads(pq.read_schema(f).metadata[b"huggingface"])
        assert meta["info"]["features"]["image"] == {"_type": "Image"}
        tab = pq.read_table(f).to_pandas()
        split = f.name.split("-")[0]
        for _, row in tab.iterrows():
            im = cv2.imdecode(np.frombuffer(row["image"]["bytes"], np.uint8), cv2.IMREAD_COLOR)
            assert im.shape[1] == row.crop_x1 - row.crop_x0 and im.shape[0] == row.crop_y1 - row.crop_y0
            G = np.array([list(r) for r in row["rotation"]], dtype=float).reshape(3, 3)
            k = idx[(row.camera, row.person_id, row.frame)]
            np.testing.assert_allclose(G, A[k].T, atol=1e-9)
            np.testing.assert_allclose(get_R_6drepnet(*np.deg2rad([row.pitch, row.yaw, row.roll])), G, atol=1e-9)
            cams.setdefault(row.camera, set()).add(split)
        total += len(tab)
    assert total > 0 and all(len(s) == 1 for s in cams.values())  # camera groups never in two splits
    try:
        import datasets  # noqa: F401
    except ImportError:
        return
    ds = datasets.load_dataset("parquet", data_dir=str(out / "data"))
    assert sum(len(v) for v in ds.values()) == total


# --------------------------------------------------------------------------------------------- read back
def _open_or_skip(path):
    from hpe_cli.errors import HpeError
    from hpe_cli.io import read_table

    try:
        t = read_table(path)
    except HpeError as exc:  # helper `data` adds COCO JSON and annotation.txt to open_table
        pytest.skip(f"open_table cannot read {path.name} yet: {exc}")
    if not {"pitch", "yaw", "roll"} <= set(t.columns):
        pytest.skip(f"open_table does not read {path.name} as labels yet (columns {list(t.columns)[:5]})")
    return t


def test_read_back_through_open_table(pizza, tmp_path):
    path, t = pizza
    assert export(path, tmp_path / "w", "--layout", "whenet", "-q").exit_code == 0
    assert export(path, tmp_path / "d", "--layout", "directmhp", "--split", DMHP_SPLIT, "-q").exit_code == 0
    lines = (tmp_path / "w" / "train" / "annotation.txt").read_text().splitlines()
    back = _open_or_skip(tmp_path / "w" / "train" / "annotation.txt")
    want = np.array([[float(v) for v in (l.split(",")[2], l.split(",")[1], l.split(",")[3])] for l in lines])
    np.testing.assert_allclose(back[["pitch", "yaw", "roll"]].to_numpy(float), want, atol=1e-12)
    coco = json.loads((tmp_path / "d" / "annotations" / "coco_style_train.json").read_text())
    back = _open_or_skip(tmp_path / "d" / "annotations" / "coco_style_train.json")
    np.testing.assert_allclose(
        back[["pitch", "yaw", "roll"]].to_numpy(float),
        np.array([a["euler_angles"] for a in coco["annotations"]]),
        atol=1e-12,
    )
    np.testing.assert_allclose(
        back[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy(float),
        np.array([a["bbox"] for a in coco["annotations"]]),
        atol=1e-9,
    )


def test_coco_export_is_an_export_input(pizza, tmp_path):
    """DirectMHP's COCO JSON (read by open_table) exports again: same rotations, now as WHENet crops."""
    path, t = pizza
    assert export(path, tmp_path / "d", "--layout", "directmhp", "--split", DMHP_SPLIT, "-q").exit_code == 0
    coco = tmp_path / "d" / "annotations" / "coco_style_train.json"
    try:
        from hpe_cli.io import read_table

        if "bbox_x" not in read_table(coco).columns:
            pytest.skip("open_table does not read COCO boxes yet")
    except Exception as exc:  # noqa: BLE001 - reader not there yet
        pytest.skip(f"open_table cannot read COCO yet: {exc}")
    out = tmp_path / "w"
    r = hpe("export", coco, "-o", out, "--layout", "whenet", "--images", tmp_path / "d" / "images" / "train", "-q")
    assert r.exit_code == 0, r.output
    lines = (out / "train" / "annotation.txt").read_text().splitlines()
    n = len(json.loads(coco.read_text())["annotations"])
    assert len(lines) == n
    A = table_A(t)
    for line in lines:
        _, yaw, pitch, roll = line.split(",")
        Aw = canonical_A([[float(pitch), float(yaw), float(roll)]])[0]
        assert min(np.abs(A - Aw).max((1, 2))) < 1e-9
