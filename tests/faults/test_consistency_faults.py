"""Faults of ``hpe audit --consistency`` and ``--exclude`` (export/convert), in the harness's style.

Bad landmarks are either one error line naming the file (and line/row) with exit 1, or rows
"not checked" with the reason; usage errors exit 2. Always: no traceback, nothing written after a
failure (no partial output, no temp files), the input unchanged, and after success every input row
is in ``-o`` (with its note) or in the rejects.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from conftest import hpe

from .conftest import ROOT, check_failed, make_images, temp_files, tree

sys.path.insert(0, str(ROOT / "benchmarks"))


@pytest.fixture(scope="module")
def lm68(tmp_path_factory):
    """40 rows of 68 projected landmarks (the benchmark's table) as a DataFrame."""
    from consistency import make_table

    path = tmp_path_factory.mktemp("lm68") / "t.parquet"
    make_table(40, path, seed=5)
    return pq.read_table(path).to_pandas()


def _outputs(tmp):
    return {"-o": tmp / "out.parquet", "--json": tmp / "r.json", "--suspects": tmp / "s.csv"}


def _audit(path, tmp, *extra):
    o = _outputs(tmp)
    args = ["audit", path, "--consistency", "-q", *extra]
    for k, v in o.items():
        args += [k, v]
    return hpe(*args), o


def _failed(res, o, tmp, snap, name, codes=(1,)):
    line = check_failed(res, name, codes)
    assert not any(p.exists() for p in o.values())
    assert not temp_files(tmp)
    assert tree(tmp) == snap  # the input unchanged, nothing added
    return line


def _ok(res, o, tmp, n_rows):
    assert res.exit_code == 0, res.output
    assert not temp_files(tmp)
    out = pq.read_table(o["-o"]).to_pandas()
    assert len(out) == n_rows  # every row is in the output, with its note
    return out, json.loads(o["--json"].read_text())["consistency"]


def _lm_cols(n):
    return [f"lm{i}_{a}" for i in range(n) for a in "xy"]


@pytest.mark.parametrize("n_points", [30, 69])
def test_a_landmark_count_of_no_scheme_is_one_line_naming_the_file(lm68, tmp_path, n_points):
    t = lm68[["image", "pitch", "yaw", "roll"] + _lm_cols(68)[: 2 * min(n_points, 68)]].copy()
    for i in range(68, n_points):
        t[f"lm{i}_x"] = 1.0
        t[f"lm{i}_y"] = 1.0
    path = tmp_path / "t.csv"
    t.to_csv(path, index=False)
    snap = tree(tmp_path)
    res, o = _audit(path, tmp_path)
    line = _failed(res, o, tmp_path, snap, path.name)
    assert f"got {n_points}" in line and "68 (ibug68)" in line, line


def test_a_landmark_column_without_its_pair_is_one_line_naming_the_file(lm68, tmp_path):
    path = tmp_path / "t.parquet"
    lm68.drop(columns=["lm67_y"]).to_parquet(path)
    snap = tree(tmp_path)
    res, o = _audit(path, tmp_path)
    line = _failed(res, o, tmp_path, snap, path.name)
    assert "got 67" in line, line


def test_invisible_nan_and_degenerate_landmarks_are_rows_not_checked_with_the_reason(lm68, tmp_path):
    t = lm68.copy()
    xs, ys = [f"lm{i}_x" for i in range(68)], [f"lm{i}_y" for i in range(68)]
    t.loc[0, xs + ys] = -1.0  # AFLW's "not visible" on every point
    t.loc[1, xs + ys] = np.nan  # no landmarks at all
    t.loc[2, xs[17:30] + ys[17:30]] = np.nan  # some points missing: still fitted
    t.loc[3, xs] = 200.0  # every point equal: a fit that cannot converge
    t.loc[3, ys] = 150.0
    t.loc[4, xs] = np.linspace(100, 300, 68)  # collinear points
    t.loc[4, ys] = 100.0
    t.loc[5, xs[17:]] = -1.0  # only 5 inner points left
    t.loc[5, ys[17:]] = -1.0
    t.loc[5, xs[17:22]] = 100.0 + np.arange(5)
    t.loc[5, ys[17:22]] = 100.0 + np.arange(5) ** 2
    t.loc[6, ["pitch", "yaw", "roll"]] = np.nan  # a label that is not a rotation
    t.loc[7, xs[:3]] = np.inf  # jaw points (unused) infinite
    path = tmp_path / "t.csv"
    t.to_csv(path, index=False)
    before = path.read_bytes()
    res, o = _audit(path, tmp_path)
    out, c = _ok(res, o, tmp_path, len(t))
    assert path.read_bytes() == before
    note = out["consistency_note"]
    few = "landmarks: fewer than 6 visible landmarks"
    assert few in note[0] and few in note[1] and few in note[5], list(note[:6])
    assert "landmarks: degenerate landmarks" in note[3] and "landmarks: degenerate landmarks" in note[4]
    assert "landmarks: label not finite" in note[6]
    for i in (0, 1, 3, 4, 5, 6):
        assert note[i].startswith("not checked: ") and np.isnan(out["consistency_score"][i]), (i, note[i])
    for i in (2, 7):
        assert np.isfinite(out["landmark_angle"][i]), i
    assert c["not_checked"] == 6 and c["checked"] == len(t) - 6
    assert c["landmarks"]["not_checked_reasons"]["fewer than 6 visible landmarks"] == 3
    assert sum(c["not_checked_reasons"].values()) == 6


def test_a_non_numeric_landmark_is_one_line_naming_file_and_line_or_a_reject(lm68, tmp_path):
    path = tmp_path / "t.csv"
    lm68.to_csv(path, index=False)
    lines = path.read_text().splitlines()
    cells = lines[4].split(",")
    cells[10] = "abc"  # a landmark value of data row 4 (file line 5)
    lines[4] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    snap = tree(tmp_path)
    res, o = _audit(path, tmp_path)
    line = _failed(res, o, tmp_path, snap, path.name)
    assert "line 5" in line, line
    rej = tmp_path / "rejects.csv"
    res, o = _audit(path, tmp_path, "--rejects", rej)
    out, c = _ok(res, o, tmp_path, len(lm68) - 1)
    assert len(pd.read_csv(rej)) == 1  # rows out + rejects = rows in
    assert c["rows"] == len(lm68) - 1


def test_a_parquet_landmark_column_of_text_is_one_line(lm68, tmp_path):
    t = lm68.copy()
    t["lm20_x"] = t["lm20_x"].astype(str)
    t.loc[3, "lm20_x"] = "n/a"
    path = tmp_path / "t.parquet"
    t.to_parquet(path)
    snap = tree(tmp_path)
    res, o = _audit(path, tmp_path)
    line = _failed(res, o, tmp_path, snap, path.name)
    assert "'n/a'" in line, line  # the reader's cast names the value (not yet its row)


def test_consistency_usage_errors_exit_2(lm68, tmp_path):
    path = tmp_path / "t.parquet"
    lm68.to_parquet(path)
    snap = tree(tmp_path)
    res = hpe("audit", path, "--suspects", tmp_path / "s.csv")
    _failed(res, {}, tmp_path, snap, "--consistency", codes=(2,))
    for bad in (["--max-jump", "-1"], ["--max-jump", "0"], ["--suspect-score", "abc"]):
        _failed(hpe("audit", path, "--consistency", *bad), {}, tmp_path, snap, bad[0], codes=(2,))


# --------------------------------------------------------------------------------------- --exclude
@pytest.fixture
def table(tmp_path):
    t = pd.DataFrame({"image": [f"im{i}.jpg" for i in range(6)], "pitch": 1.0, "yaw": np.arange(6) * 5.0, "roll": -2.0})
    t[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]] = [10, 20, 40, 50]
    make_images(tmp_path / "img", list(t["image"]), size=(160, 120))
    path = tmp_path / "in.csv"
    t.to_csv(path, index=False)
    return path


def _convert(inp, tmp, lst, *extra):
    out = tmp / "out.parquet"
    return hpe("convert", inp, "-o", out, "--from", "300w_lp", "--to", "300w_lp", "--exclude", lst, *extra), out


@pytest.mark.parametrize(
    "content, why",
    [
        (b"\x00\x01\x02garbage\xff\xfe", "expected"),
        (b"", ""),
        (b'image,reason\n"im1.jpg,oops\n', ""),
        (b"image,row,score\nim1.jpg,2,5.0\n", "'reason' column"),
    ],
)
def test_a_malformed_exclude_list_is_one_line_naming_it(table, tmp_path, content, why):
    lst = tmp_path / "list.csv"
    lst.write_bytes(content)
    snap = tree(tmp_path)
    res, out = _convert(table, tmp_path, lst)
    line = check_failed(res, lst.name, codes=(1, 2))
    assert why in line, line
    assert not out.exists() and not temp_files(tmp_path) and tree(tmp_path) == snap


@pytest.mark.parametrize("cmd", ["convert", "export"])
def test_an_exclude_list_with_no_key_of_the_input_is_a_usage_error_naming_it(table, tmp_path, cmd):
    lst = tmp_path / "list.csv"
    pd.DataFrame({"sequence": ["a"], "frame": [3], "reason": ["x"]}).to_csv(lst, index=False)
    snap = tree(tmp_path)
    if cmd == "convert":
        res, out = _convert(table, tmp_path, lst)
    else:
        out = tmp_path / "exp"
        res = hpe("export", table, "-o", out, "--layout", "whenet", "--images", tmp_path / "img", "--exclude", lst)
    line = check_failed(res, lst.name, codes=(2,))
    assert "none of its key columns" in line and "image" in line, line
    assert not out.exists() and not temp_files(tmp_path) and tree(tmp_path) == snap


def test_an_empty_exclude_list_excludes_nothing(table, tmp_path):
    lst = tmp_path / "list.csv"
    lst.write_text("image,row,score,reason\n")
    res, out = _convert(table, tmp_path, lst)
    assert res.exit_code == 0, res.output
    assert pq.read_table(out).num_rows == 6
    assert not temp_files(tmp_path)


def test_an_exclude_list_drops_exactly_its_rows_into_the_rejects(table, tmp_path):
    lst = tmp_path / "list.csv"
    pd.DataFrame({"image": ["im1.jpg", "im4.jpg", "not-there.jpg"], "reason": ["a", "b", "c"]}).to_csv(lst, index=False)
    rej = tmp_path / "rej.csv"
    res, out = _convert(table, tmp_path, lst, "--rejects", rej)
    assert res.exit_code == 0, res.output
    got = pq.read_table(out).column("image").to_pylist()
    assert got == [f"im{i}.jpg" for i in (0, 2, 3, 5)]
    r = pd.read_csv(rej)
    assert len(r) == 2 and all("excluded" in s for s in r.astype(str).agg(" ".join, axis=1))
