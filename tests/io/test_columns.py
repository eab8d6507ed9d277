"""Column maps, delimiters, headerless lists and the named input formats (hpe_cli.io.columns).

Each fixture file is written here from the format's description (the loader
code named in hpe_cli/io/columns.py), then read back with open_table.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from conftest import hpe
from hpe_cli.errors import HpeError
from hpe_cli.io import open_table

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"

# one label table in role order; the formats below spell it their own way
LABELS = pd.DataFrame(
    {
        "image": ["seq/a 1.jpg", "seq/b.jpg", "c.png"],
        "bbox_x": [10.0, 20.5, 0.0],
        "bbox_y": [5.0, 6.0, 7.25],
        "bbox_w": [100.0, 50.0, 64.0],
        "bbox_h": [101.0, 52.0, 64.0],
        "pitch": [-12.5, 30.25, 0.0],
        "yaw": [45.0, -170.5, 89.9],
        "roll": [3.0, -7.75, 1e-3],
    }
)


def read(path, **kw):
    src = open_table(path, with_lines=True, **kw)
    return src, pa.Table.from_batches(list(src.batches()), schema=src.schema).to_pandas()


def same_labels(frame, cols=("pitch", "yaw", "roll")):
    for c in cols:
        np.testing.assert_allclose(frame[c].to_numpy(float), LABELS[c].to_numpy(float), rtol=0, atol=1e-12)
    assert list(frame["image"]) == list(LABELS["image"])


def fmt(v):
    return repr(float(v))


# ------------------------------------------------------------------------------------------------ formats
def test_whenet_annotation_txt_sniffed(tmp_path):
    p = tmp_path / "annotation.txt"  # image,yaw,pitch,roll per line, no header
    p.write_text("".join(f"{r.image},{fmt(r.yaw)},{fmt(r.pitch)},{fmt(r.roll)}\n" for r in LABELS.itertuples()))
    src, f = read(p)
    same_labels(f)
    assert src.system == "whenet"
    assert list(f["__line__"]) == [1, 2, 3]


def test_whenet_writer_reads_back(tmp_path):
    from hpe_cli.io.whenet_txt import write_whenet

    p = tmp_path / "labels.txt"
    write_whenet(LABELS, p)
    _, f = read(p, input_format="whenet")
    same_labels(f)


def test_whenet_blank_lines_keep_file_lines(tmp_path):
    p = tmp_path / "annotation.txt"
    p.write_text("a.jpg,1,2,3\n\n\nb.jpg,4,5,6\n")
    _, f = read(p)
    assert list(f["__line__"]) == [1, 4]
    assert list(f["yaw"]) == [1, 4] and list(f["pitch"]) == [2, 5]


def test_opal23_panoptic_layout(tmp_path):
    p = tmp_path / "panoptic_ann_test.txt"
    lines = ["#;image;x_min;y_min;w;h;yaw;pitch;roll", "@;panoptic"]
    lines += [
        ";".join([r.image] + [fmt(v) for v in (r.bbox_x, r.bbox_y, r.bbox_w, r.bbox_h, r.yaw, r.pitch, r.roll)])
        for r in LABELS.itertuples()
    ]
    p.write_text("\n".join(lines) + "\n")
    src, f = read(p)  # sniffed from the '#;' header
    same_labels(f, ("pitch", "yaw", "roll", "bbox_x", "bbox_y", "bbox_w", "bbox_h"))
    assert list(f["__line__"]) == [3, 4, 5]
    src2, f2 = read(p, input_format="opal23")
    same_labels(f2)


def test_opal23_aflw_layout_with_landmarks(tmp_path):
    p = tmp_path / "aflw2000_ann.txt"
    pts = np.arange(2 * 68, dtype=float).reshape(68, 2) + 0.5
    row = ["images/image00002.jpg", "image00002", "-1.04", "-22.87", "4.9"] + [fmt(v) for v in pts.ravel()]
    p.write_text("#;image;identity;yaw;pitch;roll;pt_x;pt_yf\n" + ";".join(row) + "\n")
    _, f = read(p)
    assert f.loc[0, "identity"] == "image00002"
    assert (f.loc[0, "yaw"], f.loc[0, "pitch"], f.loc[0, "roll"]) == (-1.04, -22.87, 4.9)
    np.testing.assert_array_equal(f[[f"lm{i}_{a}" for i in range(68) for a in "xy"]].to_numpy()[0], pts.ravel())


def test_img2pose_biwi_matches_real_biwi_label():
    """img2pose's BIWI_annotations.txt first line (frame 00003) against hpe's reading of the real pose.txt."""
    pose = REAL / "biwi" / "hpdb" / "01" / "frame_00003_pose.txt"
    if not pose.exists():
        pytest.skip("real BIWI sample absent")
    import tempfile

    from hpe_cli.datasets.biwi import read_biwi
    from hpe_cli.rotation.systems import get_system

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "BIWI_annotations.txt"
        # the first line of vitoralbiero/img2pose evaluation/jupyter_notebooks/BIWI_annotations.txt
        p.write_text(
            "../../datasets/BIWI/01/frame_00003_rgb.png 7.607222981354766 3.290994605902283 -1.5666319048416875\n"
        )
        src, f = read(p)  # recognised by its name
    assert src.system == "300w_lp"
    t = read_biwi(pose)
    b, w = get_system("biwi"), get_system(src.system)
    R = b.to_canonical(b.from_angles(t[["pitch", "yaw", "roll"]].to_numpy()))
    A = w.to_canonical(w.from_angles(f[["pitch", "yaw", "roll"]].to_numpy()))
    assert np.abs(R - A).max() < 1e-5  # the file has 6-decimal pose.txt behind it


def test_celeba_pose(tmp_path):
    p = tmp_path / "CelebAMask-HQ-pose-anno.txt"
    body = "".join(f"{i}.jpg {fmt(r.yaw)} {fmt(r.pitch)} {fmt(r.roll)}\n" for i, r in enumerate(LABELS.itertuples()))
    p.write_text("3\nYaw Pitch Raw\n" + body)
    _, f = read(p)
    np.testing.assert_array_equal(f["roll"], LABELS["roll"])  # 'Raw' is roll
    np.testing.assert_array_equal(f["yaw"], LABELS["yaw"])
    assert list(f["image"]) == ["0.jpg", "1.jpg", "2.jpg"]
    assert list(f["__line__"]) == [3, 4, 5]


def test_coco_directmhp_schema(tmp_path):
    from hpe_cli.io.coco import write_coco

    p = tmp_path / "coco_style_val.json"
    frame = LABELS.copy()
    frame["lm0_x"], frame["lm0_y"] = [1.0, np.nan, 3.0], [2.0, np.nan, 4.0]
    write_coco(frame, p, width=640, height=480)
    src, f = read(p)  # sniffed
    same_labels(f, ("pitch", "yaw", "roll", "bbox_x", "bbox_y", "bbox_w", "bbox_h"))
    assert list(f["image_id"]) == [1, 2, 3] and list(f["annotation_id"]) == [1, 2, 3]
    assert list(f["image_width"]) == [640] * 3
    assert np.isnan(f.loc[1, "lm0_x"]) and f.loc[2, "lm0_y"] == 4.0
    assert list(f["__line__"]) == [1, 2, 3]


def test_coco_hand_written_two_heads_one_image(tmp_path):
    doc = {
        "images": [{"file_name": "00_00_00001147.jpg", "id": 10, "width": 1920, "height": 1080}],
        "annotations": [
            {"image_id": 10, "id": 7, "bbox": [1, 2, 3, 4], "euler_angles": [10, 20, 30]},
            {"image_id": 10, "id": 8, "bbox": [5, 6, 7, 8], "euler_angles": [-1, -2, -3]},
        ],
        "categories": [{"id": 1, "name": "person"}],
    }
    p = tmp_path / "x.json"
    p.write_text(json.dumps(doc))
    _, f = read(p, input_format="coco")
    assert list(f["image"]) == ["00_00_00001147.jpg"] * 2
    assert list(f["pitch"]) == [10, -1] and list(f["yaw"]) == [20, -2] and list(f["roll"]) == [30, -3]
    assert list(f["bbox_w"]) == [3, 7] and list(f["annotation_id"]) == [7, 8]


# ------------------------------------------------------------------------------------------------ generic text
def test_semicolon_header_and_columns_map(tmp_path):
    p = tmp_path / "list.txt"
    p.write_text(
        "File;Pitch;Yaw;Roll\n"
        + "".join(f"{r.image};{fmt(r.pitch)};{fmt(r.yaw)};{fmt(r.roll)}\n" for r in LABELS.itertuples())
    )
    _, f = read(p, delimiter=";", columns="image=File,pitch=Pitch,yaw=Yaw,roll=Roll")
    same_labels(f)
    assert list(f["__line__"]) == [2, 3, 4]


def test_headerless_with_names(tmp_path):
    p = tmp_path / "list.csv"
    p.write_text("".join(f"{r.image},{fmt(r.yaw)},{fmt(r.pitch)},{fmt(r.roll)}\n" for r in LABELS.itertuples()))
    _, f = read(p, header=False, names=["image", "yaw", "pitch", "roll"])
    same_labels(f)
    assert list(f["__line__"]) == [1, 2, 3]


def test_columns_map_on_csv_and_parquet(tmp_path):
    ren = LABELS.rename(columns={"pitch": "Pitch", "yaw": "Yaw", "roll": "Roll"})
    for p in (tmp_path / "t.csv", tmp_path / "t.parquet"):
        ren.to_csv(p, index=False) if p.suffix == ".csv" else ren.to_parquet(p, index=False)
        src = open_table(p, columns={"pitch": "Pitch", "yaw": "Yaw", "roll": "Roll"})
        f = pa.Table.from_batches(list(src.batches()), schema=src.schema).to_pandas()
        same_labels(f)


def test_tab_separated(tmp_path):
    p = tmp_path / "t.tsv"
    LABELS.to_csv(p, sep="\t", index=False)
    _, f = read(p, delimiter="\t")
    same_labels(f)


# ------------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "text,kw,msg",
    [
        ("a.jpg,1,2,3\nb.jpg,4,5\n", {"input_format": "whenet"}, "line 2: expected 4 fields"),
        ("#;image;yaw;pitch;roll\nx.jpg;1;2\n", {"input_format": "opal23"}, "line 2: expected 4 fields"),
        ("nonsense\n", {"input_format": "opal23"}, "line 1: expected OPAL's header"),
        ("5\nYaw Pitch Roll\n", {"input_format": "celeba-pose"}, "line 1: expected CelebAMask-HQ"),
    ],
)
def test_bad_lines_name_file_and_line(tmp_path, text, kw, msg):
    p = tmp_path / "in.txt"
    p.write_text(text)
    with pytest.raises(HpeError) as e:
        read(p, **kw)
    assert str(p) in str(e.value) and msg in str(e.value)
    assert "\n" not in str(e.value)


def test_bad_columns_map(tmp_path):
    p = tmp_path / "t.csv"
    LABELS.to_csv(p, index=False)
    with pytest.raises(HpeError, match="does not have"):
        open_table(p, columns="pitch=Pitch")
    with pytest.raises(HpeError, match="two columns named yaw"):
        open_table(p, columns="yaw=pitch")


def test_bad_coco(tmp_path):
    p = tmp_path / "c.json"
    p.write_text(json.dumps({"images": [], "annotations": [{"image_id": 3, "bbox": [1, 2, 3, 4]}]}))
    with pytest.raises(HpeError, match=r"annotation 1: image_id 3 is not in 'images'"):
        read(p)
    p.write_text("{not json")
    with pytest.raises(HpeError, match="not valid JSON"):
        read(p)


# ------------------------------------------------------------------------------------------------ CLI
def test_cli_convert_with_column_options(tmp_path):
    p = tmp_path / "list.txt"
    p.write_text("".join(f"{r.image};{fmt(r.yaw)};{fmt(r.pitch)};{fmt(r.roll)}\n" for r in LABELS.itertuples()))
    out = tmp_path / "o.csv"
    r = hpe(
        "convert",
        p,
        "-o",
        out,
        "--from",
        "300w_lp",
        "--to",
        "300w_lp",
        "--delimiter",
        ";",
        "--no-header",
        "--names",
        "image,yaw,pitch,roll",
        "-q",
    )
    assert r.exit_code == 0, r.output
    f = pd.read_csv(out)
    from hpe_cli.rotation.systems import get_system

    s = get_system("300w_lp")  # yaw -170.5 comes back as the other Euler solution: compare matrices
    np.testing.assert_allclose(
        s.from_angles(f[["pitch", "yaw", "roll"]].to_numpy()),
        s.from_angles(LABELS[["pitch", "yaw", "roll"]].to_numpy()),
        atol=1e-12,
    )


def test_cli_audit_reads_annotation_txt(tmp_path):
    p = tmp_path / "annotation.txt"
    p.write_text("a.jpg,10,20,30\nb.jpg,-10,5,1\n")
    r = hpe("audit", p, "--system", "whenet", "-q")
    assert r.exit_code == 0, r.output


def test_cli_usage_errors(tmp_path):
    p = tmp_path / "t.csv"
    LABELS.to_csv(p, index=False)
    r = hpe("convert", p, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "whenet", "--delimiter", "ab")
    assert r.exit_code == 2
    r = hpe("convert", p, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "whenet", "--columns-map", "pitch")
    assert r.exit_code == 2
    r = hpe(
        "convert", p, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "whenet", "--columns-map", "pitch=Nope"
    )
    assert r.exit_code == 1 and "Nope" in r.output


@pytest.mark.parametrize("cmd", ["convert", "audit", "draw", "augment", "infer", "evaluate", "export"])
def test_every_table_command_has_column_options(cmd):
    r = hpe(cmd, "--help")
    assert r.exit_code == 0
    for opt in ("--columns-map", "--delimiter", "--no-header", "--names", "--input-format"):
        assert opt in r.output


def test_cli_bad_line_is_a_reject_with_its_line(tmp_path):
    p = tmp_path / "annotation.txt"
    p.write_text("a.jpg,1,2,3\n\nb.jpg,4,5\nc.jpg,7,x,9\nd.jpg,1,1,1\n")
    out, rej = tmp_path / "o.csv", tmp_path / "rej.csv"
    r = hpe("convert", p, "-o", out, "--from", "whenet", "--to", "whenet", "--rejects", rej, "-q")
    assert r.exit_code == 0, r.output
    assert list(pd.read_csv(out)["image"]) == ["a.jpg", "d.jpg"]
    rj = pd.read_csv(rej)
    assert list(rj["row"]) == [3, 4]
    assert "expected 4 fields" in rj.loc[0, "reason"] and "pitch" in rj.loc[1, "reason"]


def test_cli_evaluate_two_inputs_share_the_options(tmp_path):
    """--columns-map renames the input that has the columns; text options leave a .mat folder alone."""
    real = REAL / "aflw2000_prnet" / "image00430.mat"
    if not real.exists():
        pytest.skip("real AFLW2000 sample absent")
    import shutil

    gt = tmp_path / "gt"
    gt.mkdir()
    shutil.copy(real, gt / "image00430.mat")
    pred = tmp_path / "annotation.txt"  # WHENet layout: image,yaw,pitch,roll; PROVENANCE: 34.45, 4.69, 7.25
    pred.write_text("image00430.mat,4.69,34.45,7.25\n")
    rep = tmp_path / "r.json"
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "whenet",
        "--gt-system",
        "300w_lp",
        "--key",
        "file",
        "--columns-map",
        "file=image",
        "--json",
        rep,
        "-q",
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(rep.read_text())
    assert doc["metrics"]["geodesic"]["max"] < 0.01  # the printed 2-decimal angles of the same rotation
