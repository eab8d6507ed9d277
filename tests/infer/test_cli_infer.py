"""``hpe infer`` end to end: code, decoders, tables, landmarks, and the system file it writes."""

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import canonical_A, hpe

FIX = Path(__file__).resolve().parents[1] / "fixtures" / "conventions"
MATRIX_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]


def report(tmp_path, *args, code=0):
    out = tmp_path / "report.json"
    res = hpe("infer", *args, "--json", out, "--overwrite")
    assert res.exit_code == code, res.output
    return json.loads(out.read_text()), res


def test_help_has_examples():
    res = hpe("infer", "--help")
    assert res.exit_code == 0 and "Examples:" in res.output and "hpe infer --callable" in res.output


@pytest.mark.parametrize(
    "args, best",
    [
        ([f"--callable={FIX}/sixdrepnet.py:get_R", "--args", "pitch,yaw,roll"], "6drepnet"),
        ([f"--callable={FIX}/lp300w.py:pose_matrix"], "300w_lp"),
        ([f"--callable={FIX}/scipy_style.py:euler_zyx", "--args", "yaw,pitch,roll", "--units", "deg"], "scipy_zyx"),
        ([f"--decoder={FIX}/tddfa_v2.py:matrix2angle", "--args", "yaw,pitch,roll"], "3ddfa_v2"),
        ([f"--decoder={FIX}/lp300w.py:full_range_from_matrix", "--args", "yaw,pitch,roll", "--units", "deg"], "whenet"),
    ],
)
def test_builtins_are_named(tmp_path, args, best):
    rep, res = report(tmp_path, *args)
    assert rep["best"] == best and rep["fit"] == "exact" and rep["max_error"] < 1e-12
    assert f"best: {best}" in res.output
    assert {"frame", "axes", "order"} <= set(rep["definition"]) and rep["runners_up"]


def test_custom_system_file_reproduces_the_callable_through_convert(tmp_path):
    sys_path = tmp_path / "made_up.toml"
    rep, res = report(
        tmp_path,
        "--callable",
        f"{FIX}/made_up.py:made_up",
        "--args",
        "roll,pitch,yaw",
        "--units",
        "deg",
        "-o",
        sys_path,
        "--name",
        "made_up",
    )
    assert rep["best"] == "custom" and sys_path.exists()
    pyr = np.random.default_rng(0).uniform(-180, 180, (40, 3))
    pd.DataFrame(pyr, columns=["pitch", "yaw", "roll"]).to_csv(tmp_path / "in.csv", index=False)
    out = tmp_path / "out.csv"
    res = hpe("convert", tmp_path / "in.csv", "-o", out, "--from", sys_path, "--to", sys_path)
    assert res.exit_code == 0, res.output
    got = pd.read_csv(out)[MATRIX_COLS].to_numpy().reshape(-1, 3, 3)
    sys.path.insert(0, str(FIX))
    from made_up import made_up

    assert np.abs(got - made_up(pyr[:, 2], pyr[:, 0], pyr[:, 1])).max() < 1e-9


def test_custom_frame_and_storage_options(tmp_path):
    sys_path = tmp_path / "s.toml"
    hpe(
        "infer",
        "--callable",
        f"{FIX}/made_up.py:made_up",
        "--args",
        "roll,pitch,yaw",
        "--units",
        "deg",
        "-o",
        sys_path,
        "--frame",
        "opencv",
        "--storage",
        "transposed",
        "-q",
    )
    text = sys_path.read_text()
    assert 'storage = "transposed"' in text and "[0, -1, 0]" in text


def test_module_path_and_refuse_overwrite(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(FIX))
    out = tmp_path / "s.toml"
    out.write_text("keep")
    res = hpe("infer", "--callable", "lp300w:pose_matrix", "-o", out)
    assert res.exit_code == 1 and "already exists" in res.output and out.read_text() == "keep"
    res = hpe("infer", "--callable", "lp300w:pose_matrix", "-o", out, "--overwrite")
    assert res.exit_code == 0 and 'name = "300w_lp"' in out.read_text()


def test_synergynet_no_exact_fit(tmp_path):
    out = tmp_path / "s.toml"
    rep, res = report(
        tmp_path, "--decoder", f"{FIX}/synergynet.py:matrix2angle_corr", "--args", "yaw,pitch,roll", "-o", out, code=1
    )
    assert rep["fit"] == "none" and rep["best"] == "none" and not out.exists()
    assert "no exact fit" in res.output and "breaks when" in res.output
    assert "Error:" in res.output and "nothing written" in res.output
    assert "300w_lp" in rep["best_partial"]["builtins"]


def test_wrong_units_hint(tmp_path):
    rep, _ = report(tmp_path, "--callable", f"{FIX}/made_up.py:made_up", "--args", "roll,pitch,yaw", code=1)
    assert rep["fit"] == "none" and "--degrees" in rep["hint"]


@pytest.mark.parametrize(
    "args, code, text",
    [
        ([], 2, "exactly one of"),
        (["--callable", "x.py:f", "--decoder", "y.py:g"], 2, "exactly one of"),
        (["--callable", f"{FIX}/lp300w.py:pose_matrix", "--args", "pitch,yaw"], 2, "three roles"),
        (["--callable", f"{FIX}/lp300w.py:nothing"], 1, "has no attribute"),
        (["--callable", f"{FIX}/missing.py:f"], 1, "no such file"),
        (["--callable", f"{FIX}/broken.py:NOT_CALLABLE"], 1, "expected a callable"),
        (["--callable", f"{FIX}/broken.py:scaled"], 1, "not orthonormal"),
        (["--callable", f"{FIX}/broken.py:raises"], 1, "model weights not found"),
        (["--callable", "no_such_module_xyz:f"], 1, "import failed"),
        (["--callable", f"{FIX}/lp300w.py:pose_matrix", "-o", "x.json"], 2, ".toml"),
    ],
)
def test_usage_and_user_errors(args, code, text):
    res = hpe("infer", *args)
    assert res.exit_code == code and text in res.output, res.output
    assert "Traceback" not in res.output


def test_table_with_matrices(tmp_path):
    pyr = np.random.default_rng(2).uniform(-90, 90, (100, 3))
    R = Rotation.from_euler("ZYX", pyr[:, [1, 0, 2]], degrees=True).as_matrix()  # SciPy yaw, pitch, roll
    df = pd.DataFrame(np.c_[pyr, R.reshape(-1, 9)], columns=["p", "y", "r", *[f"m{k}" for k in range(9)]])
    df.to_csv(tmp_path / "t.csv", index=False)
    rep, _ = report(
        tmp_path,
        tmp_path / "t.csv",
        "--angles",
        "yaw=y,pitch=p,roll=r",
        "--matrix",
        ",".join(f"m{k}" for k in range(9)),
    )
    assert rep["best"] == "scipy_zyx" and rep["mode"] == "table"
    rad = pd.DataFrame(
        np.c_[np.deg2rad(pyr), canonical_A(pyr).reshape(-1, 9)], columns=["pitch", "yaw", "roll", *MATRIX_COLS]
    )
    rad.to_parquet(tmp_path / "t.parquet")
    rep, _ = report(tmp_path, tmp_path / "t.parquet", "--units", "rad", "--matrix", "r00..r22")
    assert rep["best"] == "300w_lp"


def test_table_missing_columns(tmp_path):
    pd.DataFrame({"pitch": [1.0], "yaw": [2.0], "roll": [3.0]}).to_csv(tmp_path / "t.csv", index=False)
    res = hpe("infer", tmp_path / "t.csv")
    assert res.exit_code == 1 and "neither matrix columns" in res.output
    res = hpe("infer", tmp_path / "t.csv", "--matrix", "q00..q22")
    assert res.exit_code == 1 and "missing column(s) q00" in res.output


def test_landmark_table_in_image_frame(tmp_path):
    from hpe_cli.geometry.template import reference_template

    rng = np.random.default_rng(4)
    pyr = np.c_[rng.uniform(-40, 40, 30), rng.uniform(-80, 80, 30), rng.uniform(-30, 30, 30)]
    pts = 90 * np.einsum("nij,pj->npi", canonical_A(pyr), reference_template()) + rng.normal(0, 0.5, (30, 68, 3))
    pts[..., 1] = 450 - pts[..., 1]  # image rows go down
    cols = {f"lm3d{i}_{a}": pts[:, i, k] for i in range(68) for k, a in enumerate("xyz")}
    df = pd.DataFrame({"pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2], **cols})
    df.to_parquet(tmp_path / "faces.parquet")
    rep, res = report(tmp_path, tmp_path / "faces.parquet")
    assert rep["best"] == "300w_lp" and rep["fit"] == "clear" and rep["rms_residual_deg"] < 1.5
    # read in a wrong frame the faces are mirrored: the template cannot fit them, whatever the residuals say
    for wrong in ("canonical", "opencv"):
        rep, res = report(tmp_path, tmp_path / "faces.parquet", "--landmark-frame", wrong, code=1)
        assert rep["fit"] == "poor" and "fits the landmarks poorly" in res.output and "no system explains" in res.output


def test_aflw2000_landmarks(tmp_path, realdata):
    sys_path = tmp_path / "aflw.toml"
    rep, res = report(tmp_path, realdata / "aflw2000_prnet", "-o", sys_path)
    assert rep["best"] == "300w_lp" and rep["fit"] == "clear" and rep["mode"] == "landmarks"
    assert len(rep["per_face"]) == 16 and all(f["id"].endswith(".mat") for f in rep["per_face"])
    assert "best: 300w_lp" in res.output and 'name = "300w_lp"' in sys_path.read_text()
    by = {r: h["rms_residual_deg"] for h in rep["hypotheses"] for r in h["readings"]}
    assert by["3ddfa_v2"] > 10 * by["300w_lp"]
    assert by["6drepnet (stored matrix read as active)"] > 10 * by["300w_lp"]


# a repository layout written at test time (pytest's doctest collection would import these files on its own)
PKG_FILES = {
    "pkg_repo/headpose/__init__.py": "",
    "pkg_repo/headpose/geometry/__init__.py": "",
    "pkg_repo/headpose/geometry/build.py": '"""A module deep in a package with a parent-relative import: get_R = Rz(r) Ry(y) Rx(p) (6DRepNet\'s, per SPEC)."""\nfrom ..rotations import rx, ry, rz\n\n\ndef get_R(pitch, yaw, roll):\n    return rz(roll) @ ry(yaw) @ rx(pitch)\n\n\ndef hopenet_like(pitch, yaw, roll):\n    """300W-LP\'s A (the matrix Hopenet\'s draw_axis projects): left-handed X-Y-Z."""\n    return (rz(roll) @ ry(yaw) @ rx(pitch)).T\n',
    "pkg_repo/headpose/rotations.py": '"""Elemental rotations of a small package (imported with ``from ..rotations import``)."""\nimport numpy as np\n\n\ndef rx(a):\n    c, s = np.cos(a), np.sin(a)\n    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])\n\n\ndef ry(a):\n    c, s = np.cos(a), np.sin(a)\n    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])\n\n\ndef rz(a):\n    c, s = np.cos(a), np.sin(a)\n    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])\n',
    "tddfa_repo/utils/functions.py": '"""Helpers a sibling module imports relatively (layout of 3DDFA_V2\'s utils/, which has no __init__.py)."""\nimport math\n\n\ndef safe_cos(x):\n    return math.cos(x)\n',
    "tddfa_repo/utils/pose.py": '"""A 3DDFA_V2-style decoder in a folder without __init__.py that imports its sibling relatively.\n\nSame layout as 3DDFA_V2\'s utils/pose.py (``from .functions import ...``); the\ndecoder itself is written from SPEC section 3 (yaw, pitch, roll in radians).\n"""\nimport math\n\nfrom .functions import safe_cos\n\n\ndef matrix2angle(R):\n    s = R[2][0]\n    if s > 0.998:\n        return math.pi / 2, math.atan2(-R[0][1], -R[0][2]), 0.0\n    if s < -0.998:\n        return -math.pi / 2, math.atan2(R[0][1], R[0][2]), 0.0\n    yaw = math.asin(s)\n    c = safe_cos(yaw)\n    return yaw, math.atan2(R[2][1] / c, R[2][2] / c), math.atan2(R[1][0] / c, R[0][0] / c)\n',
}


@pytest.fixture
def PKG(tmp_path):
    root = tmp_path / "repos"
    for rel, text in PKG_FILES.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return root


def test_file_inside_folder_with_relative_import(tmp_path, PKG):
    """3DDFA_V2's utils/pose.py layout: `from .functions import` in a folder without __init__.py."""
    rep, res = report(tmp_path, "--decoder", f"{PKG}/tddfa_repo/utils/pose.py:matrix2angle", "--args", "yaw,pitch,roll")
    assert rep["best"] == "3ddfa_v2", res.output


def test_module_with_path_root(tmp_path, PKG):
    rep, res = report(
        tmp_path, "--decoder", "utils.pose:matrix2angle", "--path", f"{PKG}/tddfa_repo", "--args", "yaw,pitch,roll"
    )
    assert rep["best"] == "3ddfa_v2", res.output


def test_file_deep_in_package_imported_as_package_module(tmp_path, PKG):
    rep, res = report(tmp_path, "--callable", f"{PKG}/pkg_repo/headpose/geometry/build.py:get_R")
    assert rep["best"] == "6drepnet", res.output
    assert "biwi" in rep["reproduced_by"]  # BIWI's Rz Ry Rx is the same function (TriNet's BIWI vectors too)


def test_lists_every_builtin_reproducing_the_function(tmp_path, PKG):
    rep, res = report(tmp_path, "--callable", f"{PKG}/pkg_repo/headpose/geometry/build.py:hopenet_like")
    assert rep["best"] == "300w_lp" and "whenet" in rep["also_matches"]["names"]
    assert "also reproduced by built-in" in res.output and "whenet" in res.output


@pytest.mark.parametrize(
    "func, kind, order, storage, same",
    [
        ("to_rotvec", "rotvec", None, "active", "img2pose"),
        ("to_quat_inverse", "quaternion", "xyzw", "transposed", None),
        ("to_6d", "6d", [0, 1], "active", "6drepnet_6d"),
    ],
)
def test_decoder_returning_stored_values(tmp_path, func, kind, order, storage, same):
    out = tmp_path / "found.toml"
    rep, res = report(tmp_path, "--decoder", f"{FIX}/stored_values.py:{func}", "--returns", "stored", "-o", out)
    assert rep["fit"] == "exact" and rep["storage_form"]["kind"] == kind and rep["best"] == "custom", res.output
    assert (same in rep["reproduced_by"]) if same else rep["reproduced_by"] == []
    assert rep["system"]["storage"] == storage
    text = out.read_text()
    assert f'storage_kind = "{kind}"' in text


def test_decoder_returning_unknown_width(tmp_path):
    rep, res = report(tmp_path, "--decoder", f"{FIX}/stored_values.py:five_numbers", "--returns", "stored", code=1)
    assert rep["fit"] == "none" and "no storage form returns 5 numbers" in res.output


def test_written_system_loads_back_even_when_it_differs_from_the_builtin(tmp_path):
    """6DRepNet's get_R takes radians; the built-in 6drepnet says degrees: the file gets its own name."""
    out = tmp_path / "s.toml"
    res = hpe("infer", "--callable", f"{FIX}/sixdrepnet.py:get_R", "-o", out, "-q")
    assert res.exit_code == 0, res.output
    assert 'name = "6drepnet_as_inferred"' in out.read_text()
    labels = tmp_path / "l.csv"
    pd.DataFrame({"pitch": [10.0], "yaw": [20.0], "roll": [30.0]}).to_csv(labels, index=False)
    res = hpe("convert", labels, "-o", tmp_path / "o.csv", "--from", out, "--to", "6drepnet", "-q")
    assert res.exit_code == 0, res.output


def test_data_table_with_stored_rotation_vectors_and_quaternions(tmp_path):
    """A table of angles plus rotation vectors / quaternions (no r00..r22): the rotations are read through the
    storage kernels and the search names the angle convention. Oracle: SciPy builds the stored values of the
    OpenCV-frame matrix F A F (img2pose's storage) from 300W-LP angles written out by hand."""
    import json

    import numpy as np
    import pandas as pd
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    pyr = np.column_stack([rng.uniform(-80, 80, 60), rng.uniform(-85, 85, 60), rng.uniform(-80, 80, 60)])
    p, y, r = np.deg2rad(pyr).T
    Rx = lambda a: np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])  # noqa: E731
    Ry = lambda a: np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])  # noqa: E731
    Rz = lambda a: np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])  # noqa: E731
    F = np.diag([1.0, -1.0, -1.0])
    M = np.stack([F @ (Rz(c) @ Ry(b) @ Rx(a)).T @ F for a, b, c in zip(p, y, r)])
    rot = Rotation.from_matrix(M)
    frame = pd.DataFrame(pyr, columns=["pitch", "yaw", "roll"])
    frame[["rx", "ry", "rz"]] = rot.as_rotvec()
    q = rot.as_quat()  # x, y, z, w
    frame[["qx", "qy", "qz", "qw"]] = q
    src = tmp_path / "t.csv"
    frame.to_csv(src, index=False)
    for extra in ([], ["--rotations", "quaternion-xyzw:qx,qy,qz,qw"]):
        report = tmp_path / f"r{len(extra)}.json"
        res = hpe("infer", src, "--angles", "pitch,yaw,roll", *extra, "--json", report, "-q")
        assert res.exit_code == 0, res.output
        rep = json.loads(report.read_text())
        assert rep["fit"] == "exact" and rep["best"] in ("opencv", "img2pose"), rep.get("best")
        assert rep["rotation_columns"]["kind"] == ("rotvec" if not extra else "quaternion-xyzw")
    res = hpe("infer", src, "--angles", "pitch,yaw,roll", "--rotations", "rotvec:rx,ry")
    assert res.exit_code == 2 and "expected 3 columns" in res.output


def test_data_rows_that_cannot_be_used_go_to_rejects_or_stop_the_run(tmp_path):
    """hpe infer DATA: a row whose angles or matrix are not finite is not silently left out of the search: without
    --rejects it is one error line naming the file and line (exit 1); with --rejects it is set aside with its
    reason and the rest is searched (the same system as the clean table); --strict refuses it again."""
    import numpy as np
    import pandas as pd
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    pyr = rng.uniform(-60, 60, (40, 3))
    R = Rotation.from_euler("ZYX", pyr[:, [2, 1, 0]], degrees=True).as_matrix()  # any fixed convention
    t = pd.DataFrame(pyr, columns=["pitch", "yaw", "roll"])
    for i in range(3):
        for j in range(3):
            t[f"r{i}{j}"] = R[:, i, j]
    clean = tmp_path / "clean.csv"
    t.to_csv(clean, index=False)
    t.loc[5, "yaw"] = np.nan
    t.loc[9, "r11"] = np.inf
    bad = tmp_path / "bad.csv"
    t.to_csv(bad, index=False)
    res = hpe("infer", bad)
    assert res.exit_code == 1, res.output
    assert f"{bad}: line 7: angle not finite" in res.output  # row 5 -> line 7 (header = line 1)
    rej = tmp_path / "rej.csv"
    res = hpe("infer", bad, "--rejects", rej, "--json", tmp_path / "b.json")
    assert res.exit_code == 0, res.output
    r = pd.read_csv(rej)
    assert r["row"].tolist() == [7, 11] and r["reason"].str.contains("not finite").all()
    res = hpe("infer", clean, "--json", tmp_path / "c.json")
    assert res.exit_code == 0, res.output
    import json

    a, b = json.loads((tmp_path / "b.json").read_text()), json.loads((tmp_path / "c.json").read_text())
    assert a["fit"] == b["fit"] == "exact"
    assert a["system"]["name"] == b["system"]["name"] and a["system"].get("sequence") == b["system"].get("sequence")
    res = hpe("infer", bad, "--rejects", tmp_path / "r2.csv", "--strict")
    assert res.exit_code == 1 and not (tmp_path / "r2.csv").exists()


def test_unparseable_rows_are_rejects_with_a_rejects_file(tmp_path):
    """infer --rejects: a row the reader cannot parse (a word in an angle column) is a reject with its file line,
    like a missing value, instead of the end of the run (issue 35); without --rejects it is still the error."""
    import pandas as pd

    root = Path(__file__).resolve().parents[2]
    src = tmp_path / "p.csv"
    r = hpe(
        "convert", root / "sample_data" / "labels_300wlp.csv", "-o", src, "--from", "300w_lp", "--to", "6drepnet", "-q"
    )
    assert r.exit_code == 0, r.output
    df = pd.read_csv(src)
    df["pitch"] = df["pitch"].astype(object)
    df.loc[2, "pitch"] = "oops"  # file line 4
    df.loc[4, "pitch"] = None  # file line 6
    df.to_csv(src, index=False)
    rej = tmp_path / "rej.csv"
    r = hpe("infer", src, "--rejects", rej)
    assert r.exit_code == 0, r.output
    assert "best: 6drepnet (exact; max Frobenius error < 1e-12 over 202 samples)" in r.output
    got = pd.read_csv(rej)
    assert got["row"].tolist() == [4, 6]
    assert got["reason"].tolist() == ["non-numeric value in pitch", "angle not finite (missing, NaN or infinite)"]
    r = hpe("infer", src)
    assert r.exit_code == 1 and f"{src}: line 4: non-numeric value in pitch" in r.output
