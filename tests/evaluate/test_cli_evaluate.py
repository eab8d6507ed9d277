"""``hpe evaluate`` end to end (CliRunner): real AFLW2000 samples, outputs, breakdowns, bad input."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe

REALDATA = Path(__file__).resolve().parents[3] / "shared" / "realdata"
AFLW = REALDATA / "aflw2000_prnet"
needs_data = pytest.mark.skipif(not AFLW.is_dir(), reason="shared/realdata not available")

JSON_KEYS = {"n", "systems", "metrics", "protocols", "align"}
METRIC_KEYS = {
    "geodesic": {"mean", "median", "p90", "p95", "max", "within_5", "within_10", "within_15", "within_30"},
    "maev": {"left", "down", "front", "mean"},
    "frobenius": {"mean"},
    "mae_wrapped": {"pitch", "yaw", "roll", "mean"},
    "mae_best_of_two": {"pitch", "yaw", "roll", "mean"},
}


def _gt_table(tmp_path, n=40, seed=0, name="gt.csv"):
    rng = np.random.default_rng(seed)
    df = pd.DataFrame(
        {
            "image": [f"img{i:03d}.jpg" for i in range(n)],
            "pitch": rng.uniform(-60, 60, n),
            "yaw": rng.uniform(-85, 85, n),
            "roll": rng.uniform(-60, 60, n),
            "sequence": np.where(np.arange(n) % 2, "a", "b"),
        }
    )
    path = tmp_path / name
    df.to_csv(path, index=False)
    return path, df


@needs_data
def test_aflw2000_against_itself_in_6drepnet_is_zero(tmp_path):
    conv = tmp_path / "pred6d.parquet"
    r = hpe("convert", AFLW, "-o", conv, "--from", "300w_lp", "--to", "6drepnet")
    assert r.exit_code == 0, r.output
    out, rep = tmp_path / "err.parquet", tmp_path / "rep.json"
    r = hpe("evaluate", conv, AFLW, "--pred-system", "6drepnet", "--gt-system", "300w_lp", "-o", out, "--json", rep)
    assert r.exit_code == 0, r.output
    report = json.loads(rep.read_text())
    n = len(list(AFLW.glob("*.mat")))
    assert report["n"]["pairs"] == n and report["n"]["missing"] == 0 and report["n"]["invalid"] == 0
    m = report["metrics"]
    for block in m.values():
        for k, v in block.items():
            if not k.startswith("within"):
                assert abs(v) < 1e-4, (k, v)  # float32 precision of Pose_Para
    for name, p in report["protocols"].items():
        assert p["mean"] < 1e-4, name
    rows = pd.read_parquet(out)
    assert len(rows) == n and rows["geodesic"].max() < 1e-4
    assert {"image", "gt_pitch", "pred_yaw", "err_roll", "geodesic", "maev_left", "maev_down", "maev_front"} <= set(
        rows
    )  # the .mat reader's key (image)


@needs_data
def test_aflw2000_with_yaw_sign_flipped_gives_large_errors(tmp_path):
    conv = tmp_path / "pred6d.parquet"
    hpe("convert", AFLW, "-o", conv, "--from", "300w_lp", "--to", "6drepnet")
    df = pd.read_parquet(conv)[["file", "pitch", "yaw", "roll"]]
    df["yaw"] = -df["yaw"]
    flipped = tmp_path / "flipped.csv"
    df.to_csv(flipped, index=False)
    out = tmp_path / "err.csv"
    r = hpe(
        "evaluate", flipped, AFLW, "--pred-system", "6drepnet", "--gt-system", "300w_lp", "-o", out, "--json", "-", "-q"
    )
    assert r.exit_code == 0, r.output
    report = json.loads(r.output)
    rows = pd.read_csv(out).set_index("file").loc[df["file"]]
    yaw = df["yaw"].to_numpy()  # minus the true yaw
    np.testing.assert_allclose(rows["err_yaw"].to_numpy(), np.abs(2 * yaw), atol=1e-3)
    big = np.abs(yaw) > 10
    assert big.sum() >= 5
    assert (rows["geodesic"].to_numpy()[big] > 15).all()
    assert report["metrics"]["mae_wrapped"]["yaw"] > 20
    assert report["metrics"]["mae_wrapped"]["pitch"] < 1e-4


def test_json_keys_stdout_table_plots_breakdowns(tmp_path):
    gt, df = _gt_table(tmp_path)
    pred = tmp_path / "pred.csv"
    p = df.copy()
    p["yaw"] += 3.0
    p = p.sample(frac=1.0, random_state=1)  # another row order: the join is on 'image'
    p.to_csv(pred, index=False)
    rep, plots = tmp_path / "rep.json", tmp_path / "plots"
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--json",
        rep,
        "--plots",
        plots,
        "--by",
        "sequence",
        "--yaw-bins",
        "30",
        "--protocol",
        "hopenet",
        "--protocol",
        "6drepnet",
    )
    assert r.exit_code == 0, r.output
    report = json.loads(rep.read_text())
    assert JSON_KEYS <= set(report)
    assert set(report["n"]) >= {"gt", "pred", "pairs", "missing", "invalid"}
    assert set(report["systems"]) == {"pred", "gt"}
    for k, keys in METRIC_KEYS.items():
        assert set(report["metrics"][k]) == keys
    assert set(report["protocols"]) == {"hopenet", "6drepnet"}
    assert report["protocols"]["hopenet"]["yaw"] == pytest.approx(3.0, abs=1e-9)
    assert report["protocols"]["hopenet"]["pitch"] == pytest.approx(0.0, abs=1e-9)
    assert set(report["by"]["groups"]) == {"a", "b"}
    assert sum(g["n"] for g in report["by"]["groups"].values()) == 40
    assert [b["lo"] for b in report["yaw_bins"]] == [-90, -60, -30, 0, 30, 60]
    assert sum(b["n"] for b in report["yaw_bins"]) == 40
    for f in ("error_vs_yaw.png", "geodesic_cdf.png", "error_hist.png", "index.html"):
        assert (plots / f).stat().st_size > 0
    assert "geodesic" in r.output and "hopenet" in r.output and "6drepnet" in r.output


def test_missing_invalid_unmatched_counted_and_rejected(tmp_path):
    gt, df = _gt_table(tmp_path, n=10)
    p = df.copy()
    p = p[p["image"] != "img003.jpg"]  # missing prediction
    p.loc[p["image"] == "img005.jpg", "pitch"] = np.nan  # invalid prediction
    p = pd.concat(
        [p, pd.DataFrame({"image": ["extra.jpg"], "pitch": [1.0], "yaw": [2.0], "roll": [3.0], "sequence": ["a"]})]
    )
    pred = tmp_path / "pred.csv"
    p.to_csv(pred, index=False)
    rej, rep = tmp_path / "rej.csv", tmp_path / "rep.json"
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--rejects",
        rej,
        "--json",
        rep,
        "--protocol",
        "hopenet",
    )
    assert r.exit_code == 0, r.output
    n = json.loads(rep.read_text())["n"]
    assert n == {"gt": 10, "pred": 10, "pairs": 8, "missing": 1, "invalid": 1, "unmatched_pred": 1}
    rj = pd.read_csv(rej)
    assert len(rj) == 3
    by_image = dict(zip(rj["image"], rj["reason"]))
    assert by_image["img003.jpg"].startswith("missing")
    assert by_image["img005.jpg"].startswith("invalid: prediction") and "pitch" in by_image["img005.jpg"]
    assert by_image["extra.jpg"].startswith("unmatched")
    # file lines: header = line 1, so GT row img003 (index 3) is line 5
    assert dict(zip(rj["image"], rj["line"]))["img003.jpg"] == 5
    # without --rejects (or with --strict) any set-aside row is an error and nothing is written
    out = tmp_path / "e.parquet"
    r = hpe(
        "evaluate", pred, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "-o", out, "--protocol", "hopenet"
    )
    assert r.exit_code == 1 and "--rejects" in r.output and not out.exists()
    assert len(r.output.strip().splitlines()) == 1
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "-o",
        out,
        "--rejects",
        tmp_path / "r2.csv",
        "--strict",
    )
    assert r.exit_code == 1 and not out.exists()


def test_matrix_columns_non_rotation_is_invalid(tmp_path):
    gt, df = _gt_table(tmp_path, n=6)
    from conftest import canonical_A

    A = canonical_A(df[["pitch", "yaw", "roll"]].to_numpy())
    A[2] = A[2] * 1.1  # not orthonormal
    A[4] = A[4] @ np.diag([1, 1, -1])  # a reflection
    m = pd.DataFrame(A.reshape(-1, 9), columns=[f"r{i}{j}" for i in range(3) for j in range(3)])
    m.insert(0, "image", df["image"])
    pred = tmp_path / "pred.parquet"
    m.to_parquet(pred)
    rej = tmp_path / "rej.csv"
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--pred-columns",
        "matrix",
        "--rejects",
        rej,
        "--json",
        "-",
        "-q",
        "--protocol",
        "hopenet",
    )
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["n"]["invalid"] == 2 and rep["n"]["pairs"] == 4
    assert rep["metrics"]["geodesic"]["max"] < 1e-9
    reasons = pd.read_csv(rej)["reason"].tolist()
    assert any("not orthonormal" in x for x in reasons) and any("determinant" in x for x in reasons)


def test_key_option_and_multi_person(tmp_path):
    rng = np.random.default_rng(3)
    df = pd.DataFrame(
        {
            "image": ["a", "a", "b", "b"],
            "person_id": [0, 1, 0, 1],
            "pitch": rng.uniform(-30, 30, 4),
            "yaw": rng.uniform(-30, 30, 4),
            "roll": rng.uniform(-30, 30, 4),
        }
    )
    gt = tmp_path / "gt.csv"
    df.to_csv(gt, index=False)
    pred = tmp_path / "pred.csv"
    df.iloc[::-1].to_csv(pred, index=False)
    r = hpe("evaluate", pred, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp")
    assert r.exit_code == 1
    assert "duplicate key" in r.output and "image='a'" in r.output
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--key",
        "image,person_id",
        "--json",
        "-",
        "-q",
        "--protocol",
        "hopenet",
    )
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["metrics"]["geodesic"]["max"] < 1e-9


def test_row_order_join_and_count_mismatch(tmp_path):
    gt, df = _gt_table(tmp_path, n=8)
    pred = tmp_path / "pred.csv"
    df[["pitch", "yaw", "roll"]].to_csv(pred, index=False)
    # no shared key: a usage error unless --join order says so (issue 20: joins by key only)
    r = hpe("evaluate", pred, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "-q", "--protocol", "hopenet")
    assert r.exit_code == 2 and "--key" in r.output and "--join order" in r.output
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--json",
        "-",
        "-q",
        "--protocol",
        "hopenet",
        "--join",
        "order",
    )
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["inputs"]["key"] == "row order"
    df[["pitch", "yaw", "roll"]].iloc[:7].to_csv(pred, index=False)
    r = hpe("evaluate", pred, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--join", "order")
    assert r.exit_code == 2
    assert "equal row counts" in r.output


def test_bad_input_errors(tmp_path):
    gt, df = _gt_table(tmp_path, n=5)
    bad = tmp_path / "bad.csv"
    df[["image", "pitch", "yaw"]].to_csv(bad, index=False)
    r = hpe("evaluate", bad, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp")
    assert r.exit_code == 1 and "missing column" in r.output and "roll" in r.output
    r = hpe("evaluate", gt, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--protocol", "nope")
    assert r.exit_code == 2
    r = hpe("evaluate", gt, gt, "--pred-system", "nope", "--gt-system", "300w_lp")
    assert r.exit_code == 2
    r = hpe("evaluate", gt, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--key", "person_id")
    assert r.exit_code == 1 and "person_id" in r.output
    r = hpe("evaluate", gt, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--by", "nothere")
    assert r.exit_code == 1 and "nothere" in r.output
    out = tmp_path / "o.parquet"
    out.write_text("keep")
    r = hpe("evaluate", gt, gt, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "-o", out)
    assert r.exit_code == 1 and out.read_text() == "keep"


def test_different_systems_and_align(tmp_path):
    """A whenet prediction scored on 300w_lp GT with a constant 10-degree offset removed by --align mean."""
    gt, df = _gt_table(tmp_path, n=60)
    from conftest import canonical_A
    from hpe_cli.rotation.systems import get_system

    Q = Rotation.from_euler("y", 10, degrees=True).as_matrix()
    A = Q @ canonical_A(df[["pitch", "yaw", "roll"]].to_numpy())
    w = get_system("whenet")
    pw, _, _, _ = w.to_angles(w.from_canonical(A))
    pred = tmp_path / "pred.csv"
    pd.DataFrame({"image": df["image"], "pitch": pw[:, 0], "yaw": pw[:, 1], "roll": pw[:, 2]}).to_csv(pred, index=False)
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        "whenet",
        "--gt-system",
        "300w_lp",
        "--align",
        "mean",
        "--json",
        "-",
        "-q",
    )
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["align"]["offset_deg"] == pytest.approx(10.0, abs=1e-6)
    assert rep["align"]["before"]["metrics"]["geodesic"]["mean"] == pytest.approx(10.0, abs=1e-6)
    assert rep["metrics"]["geodesic"]["max"] < 1e-6


def test_help_has_examples_and_sources():
    r = hpe("evaluate", "--help")
    assert r.exit_code == 0
    for s in (
        "Examples:",
        "test_hopenet.py",
        "FSANET_test.py",
        "sixdrepnet/test.py",
        "sixdrepnet360/test.py",
        "utils/mae.py",
        "evaluator.py",
        "calc_error.py",
        "aflw_2000_3d_evaluation.ipynb",
        "benchmark.py",
    ):
        assert s in r.output, s


@pytest.mark.parametrize("name", ["img2pose", "6drepnet_6d", "trinet"])
def test_prediction_in_a_native_storage_kind(tmp_path, name):
    """Rotation vectors, 6-D and vector-column systems are read through their own columns (auto)."""
    from conftest import canonical_A
    from hpe_cli.rotation.systems import get_system

    gt, df = _gt_table(tmp_path, n=12)
    s = get_system(name)
    values = s.matrix_to_values(s.from_canonical(canonical_A(df[["pitch", "yaw", "roll"]].to_numpy())))
    pred = pd.DataFrame(values, columns=s.value_columns)
    pred.insert(0, "image", df["image"])
    path = tmp_path / "pred.parquet"
    pred.to_parquet(path)
    r = hpe(
        "evaluate",
        path,
        gt,
        "--pred-system",
        name,
        "--gt-system",
        "300w_lp",
        "--json",
        "-",
        "-q",
        "--protocol",
        "hopenet",
    )
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["n"]["pairs"] == 12 and rep["metrics"]["geodesic"]["max"] < 1e-6
