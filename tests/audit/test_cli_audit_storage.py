"""hpe audit --decoder and audit of other storage kinds (real AFLW2000 labels)."""

import json

import numpy as np
import pandas as pd
import scipy.io as sio
from scipy.spatial.transform import Rotation

from conftest import canonical_A, hpe


def test_audit_decoder_on_real_aflw2000(tmp_path, realdata):
    out = tmp_path / "r.json"
    res = hpe("audit", realdata / "aflw2000_prnet", "--decoder", "synergynet", "--json", out)
    assert res.exit_code == 0, res.output
    d = json.loads(out.read_text())["decoder"]
    assert d["reference_system"] == "300w_lp" and d["rows"] == 16 and d["decoded"] == 16
    # SynergyNet keeps 300W-LP pitch and roll exactly; its yaw is 3DDFA's asin(R20)
    assert d["d_pitch"]["max"] < 1e-9 and d["d_roll"]["max"] < 1e-9
    pp = np.array(
        [sio.loadmat(f)["Pose_Para"][0, :3] for f in sorted((realdata / "aflw2000_prnet").glob("*.mat"))], dtype=float
    )
    A = canonical_A(np.rad2deg(pp))
    want = np.abs(np.rad2deg(np.arcsin(A[:, 2, 0])) - np.rad2deg(pp[:, 1])).max()
    assert abs(d["d_yaw"]["max"] - want) < 1e-9 and d["d_yaw"]["max"] > 1
    assert "decoder synergynet vs 300w_lp" in res.output


def test_audit_rotvec_table(tmp_path):
    rv = Rotation.from_euler("xyz", [[10, 20, 30], [0, 0, 0]], degrees=True).as_rotvec()
    src = tmp_path / "rv.csv"
    pd.DataFrame({"rx": rv[:, 0], "ry": rv[:, 1], "rz": [rv[0, 2], np.nan]}).to_csv(src, index=False)
    out = tmp_path / "r.json"
    res = hpe("audit", src, "--system", "img2pose", "--json", out)
    assert res.exit_code == 0, res.output
    rep = json.loads(out.read_text())
    assert rep["label_columns"] == "rotvec" and rep["non_finite"] == 1 and rep["rows"] == 2


def test_audit_rotvec_several_batches_and_flagged_output(tmp_path):
    rv = Rotation.random(50, random_state=3).as_rotvec()
    src = tmp_path / "rv.csv"
    pd.DataFrame({"rx": rv[:, 0], "ry": rv[:, 1], "rz": rv[:, 2]}).to_csv(src, index=False)
    out = tmp_path / "f.csv"
    res = hpe("audit", src, "--system", "img2pose", "--batch-size", "7", "-o", out, "--json", tmp_path / "r.json")
    assert res.exit_code == 0, res.output
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["label_columns"] == "rotvec" and rep["rows"] == 50 and rep["not_rotation"] == 0
    assert len(pd.read_csv(out)) == 50
