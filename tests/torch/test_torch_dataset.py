"""HeadPoseDataset: label tables, .mat folders, Parquet with image bytes; crops; DataLoader with 2 workers."""

import pickle

import cv2
import numpy as np
import pandas as pd
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from conftest import REALDATA  # noqa: E402
from hpe_cli import write_labels  # noqa: E402
from hpe_cli.errors import HpeError  # noqa: E402
from hpe_cli.rotation import get_system  # noqa: E402
from hpe_cli.torch import HeadPoseDataset  # noqa: E402
from hpe_cli.torch import transforms as T  # noqa: E402

AFLW = REALDATA / "aflw2000_prnet"


def _images(tmp_path, n=6, w=64, h=48):
    rng = np.random.default_rng(0)
    names = []
    for k in range(n):
        img = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
        name = f"img{k}.png"
        cv2.imwrite(str(tmp_path / name), img)
        names.append(name)
    return names


def _table(names):
    rng = np.random.default_rng(1)
    n = len(names)
    df = pd.DataFrame({"file": names})
    df[["pitch", "yaw", "roll"]] = rng.uniform(-60, 60, (n, 3))
    df[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]] = np.tile([10.0, 8.0, 30.0, 24.0], (n, 1))
    lm = rng.uniform(12, 36, (n, 5, 2))
    for i in range(5):
        df[f"lm{i}_x"], df[f"lm{i}_y"] = lm[:, i, 0], lm[:, i, 1]
    return df


def test_parquet_table_with_system_metadata_converts_and_crops(tmp_path):
    names = _images(tmp_path)
    df = _table(names)
    path = write_labels(df, tmp_path / "labels.parquet", system="6drepnet")
    ds = HeadPoseDataset(path, system="biwi", crop=0.25, square=False)
    assert ds.label_system.name == "6drepnet" and len(ds) == 6
    s = ds[2]
    src, dst = get_system("6drepnet"), get_system("biwi")
    R = dst.from_canonical(src.to_canonical(src.from_angles(df.loc[[2], ["pitch", "yaw", "roll"]].to_numpy())))[0]
    assert np.abs(s["matrix"].double().numpy() - R).max() < 1e-6
    assert np.abs(dst.from_angles(s["angles"].double().numpy()[None])[0] - R).max() < 1e-5
    # crop = box + 25 % each side: (10 - 7.5, 8 - 6) .. (40 + 7.5, 32 + 6) -> floor/ceil
    assert tuple(s["image"].shape) == (3, 36 - 2 + 2, 48 - 2)
    assert np.allclose(s["box"].numpy(), [10 - 2, 8 - 2, 30, 24])
    lm = df.loc[2, [f"lm{i}_{a}" for i in range(5) for a in "xy"]].to_numpy(float).reshape(5, 2)
    assert np.allclose(s["landmarks"].numpy(), lm - [2, 2], atol=1e-5)
    img = cv2.imread(str(tmp_path / names[2]))[:, :, ::-1]
    assert np.array_equal(s["image"].permute(1, 2, 0).numpy()[:, :], img[2:38, 2:48])
    # square (the default): side max(30, 24) * 1.5 = 45 around the centre (25, 20): left 2, top floor(-2.5) = -3;
    # the 3 rows above the image are zeros
    sq = HeadPoseDataset(path, system="biwi", crop=0.25)[2]
    assert tuple(sq["image"].shape) == (3, 45, 45)
    assert np.allclose(sq["box"].numpy(), [10 - 2, 8 + 3, 30, 24])
    assert sq["image"][:, :3].max() == 0 and np.array_equal(sq["image"].permute(1, 2, 0).numpy()[3:], img[0:42, 2:47])


def test_csv_needs_a_label_system_and_names_bad_rows(tmp_path):
    names = _images(tmp_path, n=3)
    df = _table(names)
    df.to_csv(tmp_path / "l.csv", index=False)
    with pytest.raises(HpeError, match="label_system"):
        HeadPoseDataset(tmp_path / "l.csv")
    df.loc[1, "yaw"] = np.nan
    df.to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(HpeError, match=r"bad.csv: row 3: label is missing"):
        HeadPoseDataset(tmp_path / "bad.csv", label_system="300w_lp")


def test_parquet_with_image_bytes(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = _images(tmp_path, n=5)
    df = _table(names).drop(columns=["file"])
    blobs = [{"bytes": (tmp_path / n).read_bytes(), "path": n} for n in names]
    table = pa.Table.from_pandas(df, preserve_index=False).append_column("image", pa.array(blobs))
    pq.write_table(table, tmp_path / "hf.parquet", row_group_size=2)
    ds = HeadPoseDataset(tmp_path / "hf.parquet", label_system="300w_lp")
    for k in (4, 0, 3):
        img = cv2.imread(str(tmp_path / names[k]))[:, :, ::-1]
        assert np.array_equal(ds[k]["image"].permute(1, 2, 0).numpy(), img)
        assert np.allclose(ds[k]["angles"].numpy(), df.loc[k, ["pitch", "yaw", "roll"]].to_numpy(float), atol=1e-4)


def test_dataloader_with_two_workers_and_a_v2_transform(tmp_path):
    from torchvision.transforms import v2

    names = _images(tmp_path, n=8)
    path = write_labels(_table(names), tmp_path / "labels.parquet", system="300w_lp")
    pipe = v2.Compose(
        [
            T.RandomHorizontalFlip(p=1.0, scheme=[4, 3, 2, 1, 0]),
            v2.Resize(32),
            v2.CenterCrop(32),
            v2.ToDtype(torch.float32, scale=True),
        ]
    )
    ds = HeadPoseDataset(path, transform=pipe)
    pickle.loads(pickle.dumps(ds))
    loader = torch.utils.data.DataLoader(ds, batch_size=4, num_workers=2)
    batches = list(loader)
    assert len(batches) == 2
    b = batches[0]
    assert b["image"].shape == (4, 3, 32, 32) and b["matrix"].shape == (4, 3, 3) and b["angles"].shape == (4, 3)
    assert b["landmarks"].shape == (4, 5, 2) and b["box"].shape == (4, 4)
    pyr = _table(names)[["pitch", "yaw", "roll"]].to_numpy()[:4]
    assert np.allclose(b["angles"].numpy(), pyr * [1, -1, -1], atol=1e-4)  # hflip: (p, -y, -r)


@pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")
def test_mat_folder_real_aflw2000():
    ds = HeadPoseDataset(AFLW, system="300w_lp", landmarks="lm3d", crop=0.1)
    assert len(ds) == 16 and ds.label_system.name == "300w_lp"
    s = ds[0]
    from hpe_cli.datasets.mat import read_mat

    rec = read_mat(AFLW / "image00050.mat")
    assert np.allclose(s["angles"].double().numpy(), rec["pose"][:3], atol=1e-4)
    lm = s["landmarks"].numpy()
    assert lm.shape == (68, 2)
    # the crop is the landmark box + 10 %: the landmarks now sit inside the image with a margin
    h, w = s["image"].shape[-2:]
    assert lm[:, 0].min() > 0.05 * w and lm[:, 0].max() < 0.95 * w and lm[:, 1].min() > 0.05 * h


def test_hf_export_folder_shards_landmark_lists_and_card(tmp_path):
    """The hpe export --layout hf form: data/<split>-NNNNN-of-MMMMM.parquet, {bytes, path} images, a card naming the system."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = _images(tmp_path, n=5)
    df = _table(names)
    (tmp_path / "hf" / "data").mkdir(parents=True)
    img_type = pa.struct([pa.field("bytes", pa.binary()), pa.field("path", pa.string())])
    for shard, rows in enumerate([[0, 1, 2], [3, 4]]):
        part = df.loc[rows]
        cols = {
            "image": pa.array([{"bytes": (tmp_path / names[k]).read_bytes(), "path": names[k]} for k in rows], img_type)
        }
        for c in ["pitch", "yaw", "roll", "bbox_x", "bbox_y", "bbox_w", "bbox_h"]:
            cols[c] = pa.array(part[c].to_numpy(float))
        for a in "xy":
            cols[f"landmarks_{a}"] = pa.array(
                list(part[[f"lm{i}_{a}" for i in range(5)]].to_numpy(float)), pa.list_(pa.float64())
            )
        pq.write_table(pa.table(cols), tmp_path / "hf" / "data" / f"train-{shard:05d}-of-00002.parquet")
    (tmp_path / "hf" / "README.md").write_text(
        "---\n---\n`pitch`, `yaw`, `roll` (degrees) and the matrix `r00..r22` are in the rotation system `6drepnet`:\n"
    )
    ds = HeadPoseDataset(tmp_path / "hf", system="6drepnet")
    assert ds.label_system.name == "6drepnet" and len(ds) == 5
    for k in (4, 1, 3):
        s = ds[k]
        img = cv2.imread(str(tmp_path / names[k]))[:, :, ::-1]
        assert np.array_equal(s["image"].permute(1, 2, 0).numpy(), img)
        assert np.allclose(s["angles"].numpy(), df.loc[k, ["pitch", "yaw", "roll"]].to_numpy(float), atol=1e-4)
        lm = df.loc[k, [f"lm{i}_{a}" for i in range(5) for a in "xy"]].to_numpy(float).reshape(5, 2)
        assert np.allclose(s["landmarks"].numpy(), lm, atol=1e-5)


@pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")
def test_6drepnet_mat_list_and_crops_list(tmp_path):
    """6DRepNet's Pose_300W_LP reads <data_dir>/<name>.jpg and .mat for each line of the file list."""
    import shutil

    from hpe_cli.datasets.mat import read_mat

    split = tmp_path / "train"
    split.mkdir()
    names = ["image00050", "image00081", "image00251"]
    for n in names:
        shutil.copy(AFLW / f"{n}.mat", split)
        shutil.copy(AFLW / f"{n}.jpg", split)
    (split / "files.txt").write_text("".join(n + "\n" for n in names))
    ds = HeadPoseDataset(split / "files.txt", crop=0.0, square=False)
    assert ds.label_system.name == "300w_lp" and len(ds) == 3
    s = ds[1]
    rec = read_mat(AFLW / "image00081.mat")
    assert np.allclose(s["angles"].double().numpy(), rec["pose"][:3], atol=1e-4)
    vis = rec["pt2d"][:, np.isfinite(rec["pt2d"]).all(0)]
    assert abs(s["image"].shape[-1] - (np.ceil(vis[0].max()) - np.floor(vis[0].min()))) <= 1  # cropped to pt2d
    # crops form: files_<split>.txt with '<name>.jpg pitch yaw roll' (whenet system), images in <split>/
    (tmp_path / "files_train.txt").write_text("image00050.jpg 10.5 120.0 -3.0\nimage00081.jpg 0 -170 5\n")
    ds = HeadPoseDataset(tmp_path / "files_train.txt", system="300w_lp")
    assert ds.label_system.name == "whenet" and len(ds) == 2
    s = ds[0]
    assert tuple(s["image"].shape) == (3, 450, 450)
    w = get_system("whenet")
    R = get_system("300w_lp").from_canonical(w.to_canonical(w.from_angles([[10.5, 120.0, -3.0]])))[0]
    assert np.abs(s["matrix"].double().numpy() - R).max() < 1e-6
    (tmp_path / "bad.txt").write_text("a.jpg 1 2 x\n")
    with pytest.raises(HpeError, match=r"bad.txt: row 1: expected '<name>.jpg pitch yaw roll'"):
        HeadPoseDataset(tmp_path / "bad.txt")
