"""``hpe evaluate`` joins by key only: shuffled predictions score the same, row order needs ``--join order``."""

import json
from pathlib import Path

import pandas as pd
import pytest

from conftest import hpe

SHARED = Path(__file__).resolve().parents[3] / "shared"
AFLW = SHARED / "realdata" / "aflw2000_prnet"
PRED = SHARED / "golden" / "evaluate" / "aflw16m" / "pred.csv"
pytestmark = pytest.mark.skipif(not (AFLW.is_dir() and PRED.is_file()), reason="shared data not available")


def _eval(pred, gt, *args):
    r = hpe("evaluate", pred, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--json", "-", "-q", *args)
    return r, (json.loads(r.output) if r.exit_code == 0 else None)


def test_shuffled_predictions_score_the_same_against_the_mat_folder(tmp_path):
    shuffled = tmp_path / "shuffled.csv"
    pd.read_csv(PRED).sample(frac=1.0, random_state=7).to_csv(shuffled, index=False)
    r1, a = _eval(PRED, AFLW)
    r2, b = _eval(shuffled, AFLW)
    assert r1.exit_code == 0 and r2.exit_code == 0, (r1.output, r2.output)
    assert a["n"]["pairs"] == b["n"]["pairs"] == 16 and b["n"]["missing"] == 0 and b["n"]["unmatched_pred"] == 0
    assert a["metrics"] == b["metrics"]
    assert a["protocols"] == b["protocols"]
    # the .mat folder key is the file stem; the prediction file names the .mat: joined on the stems, and said so
    assert any("stem" in n for n in b["notes"])
    # against the golden gt.csv (same labels, same image names): the same numbers as the folder
    _, c = _eval(shuffled, PRED.parent / "gt.csv")
    assert c["protocols"]["hopenet"] == b["protocols"]["hopenet"]


def test_unmatched_rows_counted_and_rejected_on_both_sides(tmp_path):
    p = pd.read_csv(PRED)
    p = pd.concat([p.iloc[2:], pd.DataFrame({"image": ["nosuch.mat"], "pitch": [1.0], "yaw": [2.0], "roll": [3.0]})])
    pred = tmp_path / "pred.csv"
    p.to_csv(pred, index=False)
    r, _ = _eval(pred, AFLW)
    assert r.exit_code == 1 and len(r.output.strip().splitlines()) == 1
    rej = tmp_path / "rej.csv"
    r, rep = _eval(pred, AFLW, "--rejects", rej)
    assert r.exit_code == 0, r.output
    assert rep["n"]["missing"] == 2 and rep["n"]["unmatched_pred"] == 1 and rep["n"]["pairs"] == 14
    rows = pd.read_csv(rej)
    assert set(rows["side"]) == {"gt", "pred"}
    bad = rows[rows["side"] == "pred"].iloc[0]
    assert bad["input"].endswith("pred.csv") and bad["line"] == 16 and "unmatched" in bad["reason"]


def test_row_order_only_when_asked_and_counts_equal(tmp_path):
    p = pd.read_csv(PRED)[["pitch", "yaw", "roll"]]
    pred = tmp_path / "nokey.csv"
    p.to_csv(pred, index=False)
    r, _ = _eval(pred, PRED.parent / "gt.csv")
    assert r.exit_code == 2 and "--join order" in r.output
    r, rep = _eval(pred, PRED.parent / "gt.csv", "--join", "order")
    assert r.exit_code == 0 and rep["inputs"]["join"] == "order" and rep["n"]["pairs"] == 16
    p.iloc[:15].to_csv(pred, index=False)
    r, _ = _eval(pred, PRED.parent / "gt.csv", "--join", "order")
    assert r.exit_code == 2 and "equal row counts" in r.output and "15" in r.output


def test_bad_prediction_row_names_the_prediction_file_and_line(tmp_path):
    lines = PRED.read_text().splitlines()
    cells = lines[4].split(",")
    lines[4] = ",".join(cells[:3] + ["abc"])
    pred = tmp_path / "bad_pred.csv"
    pred.write_text("\n".join(lines) + "\n")
    r, _ = _eval(pred, AFLW)
    assert r.exit_code == 1
    assert r.output.startswith(f"Error: {pred}: line 5:") and len(r.output.strip().splitlines()) == 1
    p = pd.read_csv(PRED)
    p.loc[3, "pitch"] = float("nan")
    p.to_csv(pred, index=False)
    r, _ = _eval(pred, AFLW)
    assert r.exit_code == 1 and f"{pred}: line 5:" in r.output and "prediction" in r.output


def test_header_only_prediction_file_is_one_line_error(tmp_path):
    pred = tmp_path / "empty.csv"
    pred.write_text("image,pitch,yaw,roll\n")
    r, _ = _eval(pred, AFLW)
    assert r.exit_code == 1 and "empty.csv" in r.output and "header only" in r.output
    assert len(r.output.strip().splitlines()) == 1


def test_bad_parquet_prediction_row_is_named_by_row_number(tmp_path):
    p = pd.read_csv(PRED)
    p.loc[2, "yaw"] = float("nan")  # the third row of the table
    pred = tmp_path / "pred.parquet"
    p.to_parquet(pred, index=False)
    for extra in ((), ("--key", "image")):
        r, _ = _eval(pred, PRED.parent / "gt.csv", *extra)
        assert r.exit_code == 1 and f"{pred}: row 3:" in r.output, r.output
    shuffled = tmp_path / "shuffled.parquet"
    p.iloc[::-1].to_parquet(shuffled, index=False)  # in-memory join: the same row, now row 14
    r, _ = _eval(shuffled, PRED.parent / "gt.csv")
    assert r.exit_code == 1 and f"{shuffled}: row 14:" in r.output, r.output
