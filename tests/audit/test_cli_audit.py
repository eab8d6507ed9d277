"""``hpe audit`` end to end (CliRunner)."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe

REALDATA = Path(__file__).resolve().parents[3] / "shared" / "realdata"
KEYS = [
    "rows",
    "gimbal_lock",
    "near_gimbal",
    "non_canonical",
    "out_of_range",
    "non_finite",
    "not_rotation",
    "duplicates",
]

ROWS = [  # file, pitch, yaw, roll -> expected flags
    ("HELEN_2375918801_1_14.jpg", -16.0909, -89.99858, -6.8545, {"gimbal_lock", "near_gimbal"}),
    ("a.jpg", 10, 120, 5, {"non_canonical", "out_of_range"}),
    ("b.jpg", 10, 20, 5, set()),
    ("b.jpg", 10, 20, 5, {"duplicates"}),
    ("c.jpg", 10, 20, 5, set()),  # same angles, another image: not a duplicate
    ("d.jpg", np.nan, 1, 2, {"non_finite"}),
    ("e.jpg", 0, 89.5, 0, {"near_gimbal"}),
    ("f.jpg", 0, 0, 270, {"out_of_range"}),
    ("g.jpg", -170, 60, -175, set()),
]


@pytest.fixture
def table(tmp_path):
    df = pd.DataFrame([r[:4] for r in ROWS], columns=["file", "pitch", "yaw", "roll"])
    path = tmp_path / "labels.csv"
    df.to_csv(path, index=False)
    return path


def test_report_counts_and_keys(table, tmp_path):
    res = hpe("audit", table, "--json", tmp_path / "r.json", "--system", "300w_lp")
    assert res.exit_code == 0, res.output
    rep = json.loads((tmp_path / "r.json").read_text())
    assert list(rep)[:8] == KEYS
    expect = {k: sum(k in r[4] for r in ROWS) for k in KEYS[1:]}
    assert {k: rep[k] for k in KEYS[1:]} == expect
    assert rep["rows"] == len(ROWS)
    assert rep["examples"]["gimbal_lock"][0]["file"] == "HELEN_2375918801_1_14.jpg"
    assert rep["examples"]["duplicates"] == [{"row": 5, "same_as": 4}]  # file lines (header = 1)
    assert rep["details"]["near_gimbal_not_locked"] == 1


def test_flag_columns_and_only_flagged(table, tmp_path):
    out = tmp_path / "flags.parquet"
    assert hpe("audit", table, "-o", out, "-q").exit_code == 0
    df = pd.read_parquet(out)
    assert list(df.columns) == ["file", "pitch", "yaw", "roll"] + KEYS[1:] + ["flagged"]
    for i, r in enumerate(ROWS):
        assert {k for k in KEYS[1:] if df.loc[i, k]} == r[4], i
    assert df["flagged"].tolist() == [bool(r[4]) for r in ROWS]
    out2 = tmp_path / "only.csv"
    assert hpe("audit", table, "-o", out2, "--only-flagged", "-q").exit_code == 0
    assert pd.read_csv(out2)["file"].tolist() == [r[0] for r in ROWS if r[4]]


def test_exit_status_and_strict(table, tmp_path):
    assert hpe("audit", table, "-q").exit_code == 0
    assert hpe("audit", table, "-q", "--strict").exit_code == 1
    clean = tmp_path / "clean.csv"
    pd.DataFrame({"pitch": [1.0], "yaw": [2.0], "roll": [3.0]}).to_csv(clean, index=False)
    assert hpe("audit", clean, "-q", "--strict").exit_code == 0


def test_strict_failure_says_what_was_flagged(table, tmp_path):
    """--strict with flagged rows: one error line with the counts (before, exit 1 printed nothing at all)."""
    res = hpe("audit", table, "--strict", "--json", tmp_path / "r.json")
    assert res.exit_code == 1
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and "rows flagged (" in lines[0], res.output
    assert "--strict" in lines[0] and not (tmp_path / "r.json").exists()


def test_json_to_stdout_and_key_option(table):
    res = hpe("audit", table, "--json", "-", "--key", "pitch", "-q")
    rep = json.loads(res.stdout)
    # keyed on the label values only: b.jpg twice and c.jpg share (10, 20, 5)
    assert rep["duplicates"] == 2
    res = hpe("audit", table, "--key", "nope", "-q")
    assert res.exit_code == 1 and "nope" in res.output and "Traceback" not in res.output


def test_plots(table, tmp_path):
    d = tmp_path / "plots"
    assert hpe("audit", table, "--plots", d, "-q").exit_code == 0
    names = {p.name for p in d.iterdir()}
    assert names == {"yaw_hist.png", "pitch_hist.png", "roll_hist.png", "yaw_pitch_coverage.png", "index.html"}
    page = (d / "index.html").read_text()
    assert "near_gimbal" in page and "yaw_pitch_coverage.png" in page
    assert (d / "yaw_hist.png").read_bytes()[:4] == b"\x89PNG"
    res = hpe("audit", table, "--plots", d, "-q")  # refuses to overwrite
    assert res.exit_code == 1 and "--overwrite" in res.output
    assert hpe("audit", table, "--plots", d, "-q", "--overwrite").exit_code == 0


def test_matrix_input_and_radians(tmp_path):
    A = np.swapaxes(
        Rotation.from_euler("ZYX", [[30, 20, 10], [-6.8545, -89.99858, -16.0909]], degrees=True).as_matrix(), 1, 2
    )  # 300W-LP A (SPEC §2)
    bad = np.diag([1.0, 1.0, -1.0])
    M = np.concatenate([A, bad[None]]).reshape(-1, 9)
    df = pd.DataFrame(M, columns=[f"r{i}{j}" for i in range(3) for j in range(3)])
    path = tmp_path / "m.parquet"
    df.to_parquet(path)
    out = tmp_path / "r.json"
    assert hpe("audit", path, "--json", out, "-q").exit_code == 0
    rep = json.loads(out.read_text())
    assert rep["label_columns"] == "matrix"
    assert (rep["gimbal_lock"], rep["not_rotation"], rep["non_canonical"]) == (1, 1, 0)
    # the same label as 6DRepNet's stored matrix G = A.T
    dfT = pd.DataFrame(np.swapaxes(A, 1, 2).reshape(-1, 9), columns=df.columns)
    dfT.to_csv(tmp_path / "g.csv", index=False)
    assert hpe("audit", tmp_path / "g.csv", "--system", "6drepnet", "--json", tmp_path / "g.json", "-q").exit_code == 0
    assert json.loads((tmp_path / "g.json").read_text())["gimbal_lock"] == 1
    rad = tmp_path / "rad.csv"
    pd.DataFrame({"pitch": [0.0], "yaw": [np.deg2rad(120)], "roll": [0.0]}).to_csv(rad, index=False)
    res = hpe("audit", rad, "--radians", "--json", "-", "-q")
    assert json.loads(res.stdout)["non_canonical"] == 1


def test_errors_are_one_line(tmp_path):
    p = tmp_path / "x.csv"
    pd.DataFrame({"a": [1]}).to_csv(p, index=False)
    res = hpe("audit", p)
    assert res.exit_code == 1 and res.output.startswith("Error:") and "pitch" in res.output
    assert len(res.output.strip().splitlines()) == 1
    res = hpe("audit", p, "--system", "nope")
    assert res.exit_code == 2


def test_refuses_to_overwrite(table, tmp_path):
    out = tmp_path / "r.json"
    out.write_text("keep")
    res = hpe("audit", table, "--json", out, "-q")
    assert res.exit_code == 1 and out.read_text() == "keep"


def test_empty_table(tmp_path):
    p = tmp_path / "e.parquet"
    pd.DataFrame({c: pd.Series([], dtype=float) for c in ("pitch", "yaw", "roll")}).to_parquet(p)
    res = hpe("audit", p, "--json", "-", "-q", "-o", tmp_path / "f.csv")
    assert res.exit_code == 0 and json.loads(res.stdout)["rows"] == 0


def test_batches_do_not_change_results(tmp_path):
    rng = np.random.default_rng(0)
    n = 2000
    df = pd.DataFrame(
        {"pitch": rng.uniform(-180, 180, n), "yaw": rng.uniform(-95, 95, n), "roll": rng.uniform(-180, 180, n)}
    )
    df.loc[1500:1509] = df.loc[0:9].to_numpy()  # duplicates across batches
    p = tmp_path / "r.parquet"
    df.to_parquet(p)
    r1 = hpe("audit", p, "--json", "-", "-q")
    r2 = hpe("audit", p, "--json", "-", "-q", "--batch-size", "77")
    a, b = json.loads(r1.stdout), json.loads(r2.stdout)
    assert {k: a[k] for k in KEYS} == {k: b[k] for k in KEYS}
    assert a["duplicates"] == 10


@pytest.mark.skipif(not (REALDATA / "aflw2000_prnet").is_dir(), reason="realdata not available")
def test_aflw2000_mat_folder(tmp_path):
    res = hpe("audit", REALDATA / "aflw2000_prnet", "--json", "-", "-q")
    assert res.exit_code == 0, res.stderr
    rep = json.loads(res.stdout)
    # PROVENANCE.md: 16 files, every angle within +-90, none close to a lock
    assert rep["rows"] == 16 and all(rep[k] == 0 for k in KEYS[1:])
    assert "file" in rep["settings"]["duplicate_key"]
