"""Every sampling rule of ``hpe export`` lists what it skips in the rejects, with its reason: labels + rejects =
input rows, and each input row is in exactly one of them."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe

N = 24


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """24 one-head images: 2 sequences x 2 people x 6 frames; yaw turns 2 deg per frame (person 0) or 12 (person
    1); a few labels past 99 deg; 5 landmarks per head."""
    d = tmp_path_factory.mktemp("acc")
    (d / "img").mkdir()
    rng = np.random.default_rng(1)
    rows = []
    for k in range(N):
        seq, person, frame = f"s{k // 12}", (k // 6) % 2, k % 6
        name = f"img/{seq}_{person}_{frame}.jpg"
        cv2.imwrite(str(d / name), rng.integers(0, 255, (100, 120, 3), dtype=np.uint8))
        yaw = -40.0 + (2 if person == 0 else 12) * frame + (150 if k in (5, 17) else 0)
        row = {
            "image": name,
            "sequence": seq,
            "person_id": person,
            "frame": frame,
            "camera": "",
            "bbox_x": 30.0,
            "bbox_y": 20.0,
            "bbox_w": 50.0,
            "bbox_h": 60.0,
            "pitch": 5.0,
            "yaw": yaw,
            "roll": -3.0 if k != 9 else 120.0,
        }
        for i in range(5):
            row[f"lm{i}_x"], row[f"lm{i}_y"] = 40.0 + 7 * i, 40.0 + 5 * i
        rows.append(row)
    path = d / "labels.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    split_file = d / "split.csv"
    split_file.write_text("sequence,split\ns0,train\n")
    return path, split_file


RULES = {
    "min-change": (["--layout", "hf", "--min-change", "5"], "min-change"),
    "balance": (["--layout", "hf", "--balance", "yaw:20:2", "--seed", "3"], "balance"),
    "split-file": (["--layout", "hf", "--split-file", "SPLIT"], "sequence not listed in --split-file"),
    "hopenet": (["--layout", "6drepnet", "--trainer", "hopenet"], "Hopenet bins"),
    "6drepnet": (["--layout", "6drepnet"], "6DRepNet create_filename_list"),
    "6drepnet-crops-hopenet": (["--layout", "6drepnet", "--form", "crops", "--trainer", "hopenet"], "Hopenet bins"),
    "fsanet": (["--layout", "fsanet"], "outside ±99"),
    "all": (["--layout", "hf", "--min-change", "5", "--balance", "yaw:30:3", "--split-file", "SPLIT"], None),
}


@pytest.mark.parametrize("rule", sorted(RULES))
def test_labels_plus_rejects_are_the_input_rows(tmp_path, table, rule):
    path, split_file = table
    args, reason = RULES[rule]
    args = [str(split_file) if a == "SPLIT" else a for a in args]
    out, rej = tmp_path / "o", tmp_path / "rej.csv"
    r = hpe("export", path, "-o", out, "--rejects", rej, "-q", *args)
    assert r.exit_code == 0, r.output
    summary = json.loads((out / "export.json").read_text())
    rejects = pd.read_csv(rej)
    crops = pd.read_csv(out / "crops.csv")
    assert summary["labels"] == N and summary["exported"] == len(crops)
    assert summary["exported"] + len(rejects) == N
    # every input row in exactly one of them (one head per image: the image names the row)
    assert set(crops["image"]).isdisjoint(rejects["image"])
    assert set(crops["image"]) | set(rejects["image"]) == set(pd.read_csv(path)["image"])
    assert rejects["row"].is_unique and rejects["reason"].notna().all() and (rejects["reason"] != "").all()
    if reason is not None:
        assert rejects["reason"].str.startswith(reason).any(), rejects["reason"].tolist()
    assert sum(summary["rejects_per_reason"].values()) == len(rejects)
