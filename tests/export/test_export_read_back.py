"""Issue 13 "Reading back": hpe export's whenet and directmhp layouts read back by open_table give the same labels."""

import cv2
import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from conftest import hpe
from hpe_cli.io import open_table
from hpe_cli.rotation.systems import get_system


def make_set(tmp_path):
    rng = np.random.default_rng(4)
    rows = []
    (tmp_path / "img").mkdir()
    for i in range(3):
        cv2.imwrite(str(tmp_path / "img" / f"f{i}.jpg"), rng.integers(0, 255, (120, 160, 3), dtype=np.uint8))
        for h in range(2):
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
                    "pitch": 10.0 * h - 20,
                    "yaw": 25.0 * i - 30,
                    "roll": 5.0 - 3 * h,
                }
            )
    path = tmp_path / "labels.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    return path, pd.DataFrame(rows)


def matrices(frame, system):
    s = get_system(system)
    return s.to_canonical(s.from_angles(frame[["pitch", "yaw", "roll"]].to_numpy(float)))


def read_all(path):
    src = open_table(path)
    return src, pa.Table.from_batches(list(src.batches()), schema=src.schema).to_pandas()


@pytest.mark.parametrize("layout", ["whenet", "directmhp"])
def test_export_reads_back(tmp_path, layout):
    path, labels = make_set(tmp_path)
    out = tmp_path / "out"
    split = ["--split", "image:train=0.67,val=0.33"] if layout == "directmhp" else []  # DirectMHP needs a val split
    r = hpe("export", path, "-o", out, "--layout", layout, "-q", *split)
    assert r.exit_code == 0, r.output
    files = sorted(out.rglob("annotation.txt" if layout == "whenet" else "coco_style_*.json"))
    assert files
    back = []
    for f in files:
        src, frame = read_all(f)  # recognised by name / by its COCO keys
        if layout == "whenet":
            assert src.system == "whenet"
        back.append(frame)
    back = pd.concat(back, ignore_index=True)
    assert len(back) == len(labels)
    got = matrices(back, "whenet").reshape(len(back), -1)
    want = matrices(labels, "300w_lp").reshape(len(labels), -1)
    d = np.linalg.norm(got[:, None, :] - want[None, :, :], axis=2)  # every label distinct: a permutation
    match = d.argmin(axis=1)
    assert sorted(match.tolist()) == list(range(len(labels)))
    assert d[np.arange(len(back)), match].max() < 1e-9
    if layout == "directmhp":  # boxes come back too (in the exported images' pixels)
        assert np.isfinite(back[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy()).all()
