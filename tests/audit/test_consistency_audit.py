"""``hpe audit --consistency`` on real and synthetic tables: the wrong labels top the ranking, nothing else."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe
from tests.conftest import canonical_A, sample_data_script


def audit_json(path, *extra):
    res = hpe("audit", path, "--consistency", "--json", "-", "-q", *extra)
    assert res.exit_code == 0, res.output
    return json.loads(res.output)["consistency"]


def _angles_of(A):
    from hpe_cli.rotation.systems import get_system

    s = get_system("300w_lp")
    return s.to_angles(s.from_canonical(A))[0]


def _turn(axis, deg):
    axis = np.asarray(axis, dtype=float)
    return Rotation.from_rotvec(np.deg2rad(deg) * axis / np.linalg.norm(axis)).as_matrix()


# --------------------------------------------------------------------------------------- AFLW2000-3D
def test_aflw2000_folder_is_checked_with_its_21_points(realdata):
    c = audit_json(realdata / "aflw2000_prnet")
    assert c["rows"] == c["checked"] == 16 and c["not_checked"] == 0
    assert c["landmarks"]["scheme"] == "aflw21"
    assert c["landmarks"]["angle_deg"]["median"] < 10.0  # 6.7 deg
    assert c["suspects"] == 0


def test_aflw2000_labels_turned_by_30_deg_top_the_ranking(realdata, tmp_path):
    from hpe_cli.datasets.mat import read_mat_dir

    t = read_mat_dir(realdata / "aflw2000_prnet", landmarks=True)
    A = canonical_A(t[["pitch", "yaw", "roll"]].to_numpy())
    base = audit_json(realdata / "aflw2000_prnet")
    turned = {0: [0, 1, 0], 8: [1, 0, 0], 11: [0, 0, 1]}  # yaw, pitch, roll turns of rows with a small base angle
    for i, axis in turned.items():
        A[i] = _turn(axis, 30) @ A[i]
    t[["pitch", "yaw", "roll"]] = _angles_of(A)  # landmarks and images unchanged
    path = tmp_path / "turned.parquet"
    t.to_parquet(path)
    out = tmp_path / "scored.parquet"
    res = hpe("audit", path, "--consistency", "--json", tmp_path / "r.json", "-o", out, "-q")
    assert res.exit_code == 0, res.output
    c = json.loads((tmp_path / "r.json").read_text())["consistency"]
    files = [str(t["file"][i]) for i in turned]
    assert sorted(w["file"] for w in c["worst"][:3]) == sorted(files)
    assert c["suspects"] == 3
    scored = pq.read_table(out).to_pandas()
    for i in turned:
        got = scored["landmark_angle"][i]
        # triangle inequality: |angle to evidence - 30| <= the row's untouched angle (2.5-5.4 deg here)
        assert abs(got - 30.0) <= 6.0, (i, got)
    assert scored["suspect"].sum() == 3
    assert base["suspects"] == 0


# --------------------------------------------------------------------------------------- synthetic Panoptic
@pytest.fixture(scope="module")
def synthetic_labels(tmp_path_factory):
    """A synthetic sequence: person 0's landmarks turned by 25 deg at one frame before relabelling."""
    root = tmp_path_factory.mktemp("cons") / "synthseq"
    gen = sample_data_script()
    gen.make_synthetic(root, n_frames=16, n_people=2, n_cameras=8, first_frame=100, special=False)
    glitch = 108
    face = root / "hdFace3d" / f"faceRecon3D_hd{glitch:08d}.json"
    doc = json.loads(face.read_text())
    lm = np.asarray(doc["people"][0]["face70"]["landmarks"]).reshape(70, 3)
    c = lm.mean(0)
    doc["people"][0]["face70"]["landmarks"] = ((lm - c) @ _turn([0.3, 1.0, 0.2], 25).T + c).reshape(-1).tolist()
    face.write_text(json.dumps(doc))
    out = root.parent / "labels.parquet"
    res = hpe("relabel-panoptic", root, "-o", out, "-q", "--rejects", root.parent / "rej.csv")
    assert res.exit_code == 0, res.output
    return out, glitch, doc["people"][0]["id"]


def test_synthetic_panoptic_camera_offset_and_glitch(synthetic_labels, tmp_path):
    labels, glitch, pid = synthetic_labels
    t = pq.read_table(labels)
    cams = sorted(set(t.column("camera").to_pylist()))
    bad_cam = cams[3]
    pyr = np.stack([t.column(c).to_numpy() for c in ("pitch", "yaw", "roll")], 1)
    A = canonical_A(pyr)
    sel = np.array(t.column("camera").to_pylist()) == bad_cam
    A[sel] = _turn([0.2, 1.0, -0.3], 4.0) @ A[sel]  # a camera whose labels are 4 deg off
    new = _angles_of(A)
    keep = [c for c in t.column_names if not c.startswith(("r0", "r1", "r2", "pitch", "yaw", "roll"))]
    t2 = t.select(keep)
    for k, c in enumerate(("pitch", "yaw", "roll")):
        t2 = t2.append_column(c, pa.array(new[:, k]))
    t2 = t2.replace_schema_metadata(t.schema.metadata)  # keeps hpe:relabel (the calibration)
    path = tmp_path / "turned.parquet"
    pq.write_table(t2, path)
    out = tmp_path / "scored.parquet"
    res = hpe("audit", path, "--consistency", "-o", out, "--json", tmp_path / "r.json", "-q")
    assert res.exit_code == 0, res.output
    c = json.loads((tmp_path / "r.json").read_text())["consistency"]
    v = c["views"]
    assert v["cameras_with_offset"] == [bad_cam]
    entry = next(e for e in v["cameras"] if e["camera"] == bad_cam)
    assert abs(entry["offset_deg"] - 4.0) < 0.3
    assert all(e["offset_deg"] < 1.0 for e in v["cameras"] if e["camera"] != bad_cam)
    s = pq.read_table(out).to_pandas()
    glitch_rows = (s["frame"] == glitch) & (s["person_id"] == pid)
    assert glitch_rows.any()
    assert s.loc[glitch_rows, "suspect"].all()
    assert s.loc[glitch_rows, "jump_rate"].min() > 10.0  # a 25 deg turn, seen against a fast synthetic turn
    # nothing else: every other suspect is a row of the turned camera, flagged by its views
    other = s[s["suspect"] & ~glitch_rows]
    assert (other["camera"] == bad_cam).all()
    assert other["consistency_note"].str.contains("views").all()
    rest = s[~glitch_rows & (s["camera"] != bad_cam)]
    assert not rest["suspect"].any()
    assert np.nanmax(rest["jump_rate"]) < 5.0


@pytest.mark.parametrize("legacy", [[], ["--legacy-whenet"]])
def test_pizza1_own_labels_show_no_view_disagreement(realdata, tmp_path, legacy):
    out = tmp_path / "pizza1.parquet"
    res = hpe(
        "relabel-panoptic",
        realdata / "panoptic_160906_pizza1",
        "-o",
        out,
        "-q",
        "--rejects",
        tmp_path / "r.csv",
        *legacy,
    )
    assert res.exit_code == 0, res.output
    c = audit_json(out)
    v = c["views"]
    assert v["checked"] > 1000
    assert v["angle_deg"]["max"] < 1e-6
    assert v["cameras_with_offset"] == []
    assert max(e["offset_deg"] for e in v["cameras"]) < 1e-6
    assert c["landmarks"]["scheme"] == "face70"
    assert c["landmarks"]["angle_deg"]["median"] < 10.0  # 7.8 deg, perspective-corrected


# --------------------------------------------------------------------------------------- honest limits
def test_rows_without_evidence_are_not_checked(tmp_path):
    path = tmp_path / "plain.csv"
    path.write_text("image,pitch,yaw,roll\na.jpg,1,2,3\nb.jpg,nan,2,3\n")
    out = tmp_path / "o.csv"
    res = hpe("audit", path, "--consistency", "--json", tmp_path / "r.json", "-o", out, "-q")
    assert res.exit_code == 0, res.output
    c = json.loads((tmp_path / "r.json").read_text())["consistency"]
    assert c["checked"] == 0 and c["not_checked"] == 2 and c["suspects"] == 0
    assert any("no landmark columns" in r for r in c["not_checked_reasons"])
    s = pq.read_table(out).to_pandas() if out.suffix == ".parquet" else __import__("pandas").read_csv(out)
    assert s["consistency_note"].str.startswith("not checked").all()
    assert not s["suspect"].any()
    assert s["consistency_score"].isna().all()


def test_landmarks_of_an_unknown_count_are_one_line_error(tmp_path):
    cols = ["image", "pitch", "yaw", "roll"] + [f"lm{i}_{a}" for i in range(5) for a in "xy"]
    path = tmp_path / "five.csv"
    path.write_text(",".join(cols) + "\n" + ",".join(["a.jpg", "1", "2", "3"] + ["1"] * 10) + "\n")
    res = hpe("audit", path, "--consistency")
    assert res.exit_code == 1
    assert "expected 21 (aflw21), 68 (ibug68) or 70 (face70) landmark columns" in res.output
    assert str(path) in res.output and "Traceback" not in res.output


def test_too_few_visible_points_is_not_checked_with_reason(tmp_path):
    cols = ["image", "pitch", "yaw", "roll"] + [f"lm{i}_{a}" for i in range(21) for a in "xy"]
    row = ["a.jpg", "1", "2", "3"] + ["-1"] * 42  # AFLW: every point invisible
    path = tmp_path / "inv.csv"
    path.write_text(",".join(cols) + "\n" + ",".join(row) + "\n")
    c = audit_json(path)
    assert c["not_checked"] == 1
    assert c["landmarks"]["not_checked_reasons"] == {"fewer than 6 visible landmarks": 1}


def test_suspects_need_consistency(tmp_path):
    path = tmp_path / "plain.csv"
    path.write_text("image,pitch,yaw,roll\na.jpg,1,2,3\n")
    res = hpe("audit", path, "--suspects", tmp_path / "s.csv")
    assert res.exit_code == 2


def test_python_api_runs_the_same_pipeline(realdata, tmp_path):
    from hpe_cli.api import audit_file

    rep = audit_file(realdata / "aflw2000_prnet", consistency=True, suspects=tmp_path / "s.csv")
    cli_rep = audit_json(realdata / "aflw2000_prnet")
    assert rep["consistency"]["landmarks"] == cli_rep["landmarks"]
    assert (tmp_path / "s.csv").exists()


def test_plots_page_draws_the_worst_rows(realdata, tmp_path):
    from hpe_cli.datasets.mat import read_mat_dir

    t = read_mat_dir(realdata / "aflw2000_prnet", landmarks=True)
    A = canonical_A(t[["pitch", "yaw", "roll"]].to_numpy())
    A[0] = _turn([0, 1, 0], 30) @ A[0]
    t[["pitch", "yaw", "roll"]] = _angles_of(A)
    path = tmp_path / "turned.parquet"
    t.to_parquet(path)
    plots = tmp_path / "plots"
    c = audit_json(path, "--plots", plots, "--images", realdata / "aflw2000_prnet")
    page = (plots / "consistency" / "index.html").read_text()
    assert c["page"].endswith("consistency/index.html") and c["not_drawn"] == []
    assert (plots / "consistency" / "worst_1.png").stat().st_size > 1000
    assert (plots / "consistency" / "scores.png").exists()
    assert t["file"][0] in page and "fitted to the landmarks" in page
    assert (plots / "index.html").exists()  # the audit's own page is still written


def test_missing_recorded_calibration_is_one_line_error_and_nothing_written(synthetic_labels, tmp_path):
    labels, _, _ = synthetic_labels
    t = pq.read_table(labels)
    meta = dict(t.schema.metadata)
    rel = json.loads(meta[b"hpe:relabel"])
    rel["calibration"] = str(tmp_path / "gone.json")
    meta[b"hpe:relabel"] = json.dumps(rel).encode()
    path = tmp_path / "moved.parquet"
    pq.write_table(t.replace_schema_metadata(meta), path)
    out, sus = tmp_path / "o.parquet", tmp_path / "s.csv"
    res = hpe("audit", path, "--consistency", "-o", out, "--suspects", sus)
    assert res.exit_code == 1
    assert f"{tmp_path / 'gone.json'}: cannot read the calibration for --consistency" in res.output
    assert "--calibration FILE" in res.output and "Traceback" not in res.output
    assert not out.exists() and not sus.exists()
    # the calibration given on the command line is used instead
    calib = next((labels.parent / "synthseq").glob("calibration_*.json"))
    c = audit_json(path, "--calibration", calib)
    assert c["views"]["checked"] > 0


def test_suspects_may_not_overwrite_the_input(tmp_path):
    path = tmp_path / "plain.csv"
    path.write_text("image,pitch,yaw,roll\na.jpg,1,2,3\n")
    res = hpe("audit", path, "--consistency", "--suspects", path, "--overwrite")
    assert res.exit_code == 1 and "--suspects must differ from INPUT" in res.output
    assert path.read_text() == "image,pitch,yaw,roll\na.jpg,1,2,3\n"


def test_several_sequences_use_each_sequences_calibration(tmp_path):
    gen = sample_data_script()
    gen.make_synthetic(tmp_path / "seqA", n_frames=6, n_people=2, n_cameras=5, special=False)
    gen.make_synthetic(tmp_path / "seqB", n_frames=6, n_people=2, n_cameras=5, seed=7, special=False)
    out = tmp_path / "labels.parquet"
    res = hpe(
        "relabel-panoptic", tmp_path / "seqA", tmp_path / "seqB", "-o", out, "-q", "--rejects", tmp_path / "r.csv"
    )
    assert res.exit_code == 0, res.output
    c = audit_json(out)
    v = c["views"]
    assert len(v["calibration"]) == 2
    assert v["checked"] == c["rows"] and v["angle_deg"]["max"] < 1e-6
    assert v["cameras_with_offset"] == [] and c["time"]["checked"] > 0
