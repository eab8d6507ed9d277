"""The streaming COCO and WHENet writers against the whole-table writers they replace.

The oracles below are copies of the previous implementations (json.dump of one dict built from the whole
table; one str(float) line per row), kept here verbatim in substance. Both outputs are parsed and compared
value for value; WHENet's text is also compared byte for byte.
"""

import json

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from hpe_cli.io.coco import CocoWriter, write_coco
from hpe_cli.io.whenet_txt import write_whenet

BBOX = ["bbox_x", "bbox_y", "bbox_w", "bbox_h"]
ANG = ["pitch", "yaw", "roll"]


def old_coco_dict(frame, width=None, height=None, info=None):
    files = frame["image"].astype(str).to_numpy()
    uniq, first, codes = np.unique(files, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    codes = rank[codes.reshape(-1)]
    names = uniq[order]
    sizes = []
    for col, given in (("image_width", width), ("image_height", height)):
        if col in frame.columns:
            per = np.full(names.size, np.nan)
            per[codes] = frame[col].to_numpy(dtype=np.float64)
            sizes.append(per.astype(np.int64))
        else:
            sizes.append(np.full(names.size, int(given), dtype=np.int64))
    box = frame[BBOX].to_numpy(dtype=np.float64)
    ang = frame[ANG].to_numpy(dtype=np.float64)
    n_lm = sum(1 for c in frame.columns if c.startswith("lm") and c.endswith("_x"))
    if n_lm:
        xs = frame[[f"lm{i}_x" for i in range(n_lm)]].to_numpy(dtype=np.float64, na_value=np.nan)
        ys = frame[[f"lm{i}_y" for i in range(n_lm)]].to_numpy(dtype=np.float64, na_value=np.nan)
        gone = ~(np.isfinite(xs) & np.isfinite(ys))
        pts = [[x, y] for x, y in zip(np.where(gone, -1.0, xs).tolist(), np.where(gone, -1.0, ys).tolist())]
    else:
        pts = [[] for _ in range(len(frame))]
    area = np.round(box[:, 2] * box[:, 3], 4).tolist()
    image_ids = (codes + 1).tolist()
    images = [
        {"file_name": str(f), "height": int(h), "width": int(w), "id": i + 1}
        for i, (f, w, h) in enumerate(zip(names.tolist(), sizes[0].tolist(), sizes[1].tolist()))
    ]
    anns = [
        {
            "image_id": image_ids[k],
            "id": k + 1,
            "category_id": 1,
            "bbox": box.tolist()[k],
            "euler_angles": ang.tolist()[k],
            "face2d_pts": pts[k],
            "area": area[k],
            "iscrowd": 0,
            "segmentation": [],
        }
        for k in range(len(frame))
    ]
    return {
        "info": dict(info or {}),
        "licenses": [],
        "images": images,
        "annotations": anns,
        "categories": [{"supercategory": "person", "id": 1, "name": "person"}],
    }


def old_whenet_text(frame):
    cols = [frame[c].to_numpy(dtype=np.float64).tolist() for c in ("yaw", "pitch", "roll")]
    return "".join(f"{im},{y!s},{p!s},{r!s}\n" for im, y, p, r in zip(frame["image"].astype(str).tolist(), *cols))


def table(n, n_lm=5, seed=0):
    rng = np.random.default_rng(seed)
    df = pd.DataFrame({"image": [f"seq/cam{i % 7:02d}_{i // 3}.jpg" for i in range(n)]})
    for c in BBOX:
        df[c] = rng.uniform(0, 500, n)
    df.loc[::5, "bbox_x"] = 12.0  # integral floats
    for c in ANG:
        df[c] = rng.uniform(-179, 179, n) * 10.0 ** rng.integers(-8, 3, n)  # tiny and ordinary values
    df["image_width"] = 1920
    df["image_height"] = 1080
    for i in range(n_lm):
        df[f"lm{i}_x"] = rng.uniform(0, 1920, n)
        df[f"lm{i}_y"] = rng.uniform(0, 1080, n)
    if n_lm:
        df.loc[::4, "lm1_x"] = np.nan
    return df


@pytest.mark.parametrize("n_lm", [0, 5])
def test_coco_value_for_value(tmp_path, n_lm):
    df = table(3000, n_lm)
    info = {"description": "x", "n": 3}
    out = tmp_path / "c.json"
    # batches of three kinds: pandas slices, Arrow record batches, an Arrow table
    parts = [
        df.iloc[:1000],
        pa.RecordBatch.from_pandas(df.iloc[1000:2500], preserve_index=False),
        pa.Table.from_pandas(df.iloc[2500:], preserve_index=False),
    ]
    with CocoWriter(out, info=info) as w:
        for p in parts:
            w.write(p)
    got = json.loads(out.read_text())
    assert got == old_coco_dict(df, info=info)
    write_coco(df, tmp_path / "c2.json", info=info, batch_size=777)
    assert json.loads((tmp_path / "c2.json").read_text()) == got


def test_whenet_byte_for_byte(tmp_path):
    df = table(3000, 0)
    write_whenet(df, tmp_path / "a.txt", batch_size=999)
    assert (tmp_path / "a.txt").read_text() == old_whenet_text(df)
    write_whenet(iter([pa.Table.from_pandas(df.iloc[:10], preserve_index=False), df.iloc[10:]]), tmp_path / "b.txt")
    assert (tmp_path / "b.txt").read_text() == old_whenet_text(df)


def test_coco_error_leaves_nothing(tmp_path):
    df = table(100, 0)
    df.loc[70, "yaw"] = np.nan
    out = tmp_path / "c.json"
    with pytest.raises(Exception, match="row 70: expected a finite yaw"):
        write_coco(df, out, batch_size=32)
    assert not out.exists() and not list(tmp_path.iterdir())
