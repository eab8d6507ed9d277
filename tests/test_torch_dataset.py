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
    ds = HeadPoseDataset(path, system="biwi", crop=0.25)
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
    pipe = v2.Compose([T.RandomHorizontalFlip(p=1.0, scheme=[4, 3, 2, 1, 0]), v2.Resize(32),
                       v2.CenterCrop(32), v2.ToDtype(torch.float32, scale=True)])
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
