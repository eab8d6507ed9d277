"""HeadPoseDataset's packed per-row outputs (no transform) equal the per-sample path exactly, key for key."""

import cv2
import numpy as np
import pandas as pd
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from conftest import REALDATA
from hpe_cli import write_labels
from hpe_cli.torch import HeadPoseDataset

AFLW = REALDATA / "aflw2000_prnet"


def _labels(tmp_path, n=10):
    rng = np.random.default_rng(1)
    names = []
    for k in range(n):
        names.append(f"im{k}.png")
        cv2.imwrite(str(tmp_path / names[-1]), rng.integers(0, 255, (70 + k, 90, 3), dtype=np.uint8))
    df = pd.DataFrame({"file": names})
    df[["pitch", "yaw", "roll"]] = rng.uniform(-89, 89, (n, 3))
    df.loc[0, ["pitch", "yaw", "roll"]] = [90.0, 10.0, 5.0]  # gimbal lock
    box = np.column_stack(
        [rng.uniform(-5, 40, n), rng.uniform(-5, 30, n), rng.uniform(20, 50, n), rng.uniform(20, 50, n)]
    )
    box[3] = np.nan  # no box: the landmarks' box
    df[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]] = box
    lm = rng.uniform(10, 60, (n, 5, 2))
    lm[2, 1] = np.nan
    for i in range(5):
        df[f"lm{i}_x"], df[f"lm{i}_y"] = lm[:, i, 0], lm[:, i, 1]
    return write_labels(df, tmp_path / "labels.parquet", system="300w_lp")


def _same(a, b):
    assert list(a) == list(b)
    for k in a:
        if isinstance(a[k], torch.Tensor):
            assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
            assert (
                torch.equal(a[k], b[k])
                or (a[k].isnan() == b[k].isnan()).all()
                and torch.equal(a[k].nan_to_num(), b[k].nan_to_num())
            ), k
            if k == "image":
                assert a[k].stride() == b[k].stride()
        else:
            assert a[k] == b[k], k


@pytest.mark.parametrize(
    "kw",
    [
        {"crop": 0.2},
        {"crop": 0.2, "size": 48},
        {"crop": 0.1, "square": False},
        {"crop": 0.1, "square": False, "size": 40, "on_undefined": "keep"},
        {},
        {"crop": 0.3, "size": 32, "dtype": torch.float64},
        {"crop": 0.2, "landmarks": None},
    ],
)
@pytest.mark.parametrize("flip", [False, True])
def test_packed_rows_equal_the_per_sample_path(tmp_path, kw, flip):
    kw = dict(kw)
    expect = 0 if not kw and flip else None if "size" in kw and kw.get("square") is False else 10
    ds = HeadPoseDataset(
        _labels(tmp_path), crop=kw.pop("crop", None), hflip=float(flip), flip_scheme=[4, 3, 2, 1, 0], **kw
    )
    tabled = 0
    for i in range(len(ds)):
        slow = ds._finish([ds._prepare(i, flip)])[0]
        fast = ds[i]
        tabled += bool(ds._rows._tables[flip][2][i]) if flip in ds._rows._tables else 0
        _same(fast, slow)
    assert all(ds.__getitems__([3, 1])[k]["index"] == v for k, v in enumerate([3, 1]))
    assert expect is None or tabled == expect  # the rest went the per-sample way


@pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")
def test_packed_rows_equal_on_aflw2000(tmp_path):
    for flip in (0.0, 1.0):
        ds = HeadPoseDataset(AFLW, crop=0.25, size=64, hflip=flip, landmarks="lm3d")
        for i in range(len(ds)):
            _same(ds[i], ds._finish([ds._prepare(i, bool(flip))])[0])
