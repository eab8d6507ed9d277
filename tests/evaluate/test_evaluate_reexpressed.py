"""Raw-angle protocols use the angles as written; a side given in another system is converted and counted."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe

GOLD = Path(__file__).resolve().parents[3] / "shared" / "golden" / "evaluate" / "aflw16m"
pytestmark = pytest.mark.skipif(not GOLD.is_dir(), reason="shared/golden/evaluate not available")
A = ["pitch", "yaw", "roll"]


def _report(pred, gt, psys):
    r = hpe(
        "evaluate",
        pred,
        gt,
        "--pred-system",
        psys,
        "--gt-system",
        "300w_lp",
        "--json",
        "-",
        "-q",
        "--protocol",
        "hopenet",
        "--protocol",
        "opal23",
    )
    assert r.exit_code == 0, r.output
    return json.loads(r.output)


def test_prediction_in_biwi_system_is_converted_and_counted(tmp_path):
    pred, gt = pd.read_csv(GOLD / "pred.csv"), pd.read_csv(GOLD / "gt.csv")
    # oracle (SciPy): the 300W-LP matrix A = Rx(p).T Ry(y).T Rz(r).T = from_euler('XYZ', -angles); BIWI's matrix is
    # F A F (F = diag(1, -1, -1)) split as Rz(roll) Ry(yaw) Rx(pitch) = from_euler('xyz', (pitch, yaw, roll))
    A300 = Rotation.from_euler("XYZ", -pred[A].to_numpy(), degrees=True).as_matrix()
    F = np.diag([1.0, -1.0, -1.0])
    biwi = Rotation.from_matrix(F @ A300 @ F).as_euler("xyz", degrees=True)
    pb = pred.copy()
    pb[A] = biwi
    pb.to_csv(tmp_path / "pred_biwi.csv", index=False)
    rep = _report(tmp_path / "pred_biwi.csv", GOLD / "gt.csv", "biwi")
    h = rep["protocols"]["hopenet"]
    assert h["re_expressed"] == {"pred": 16, "gt": 0}
    # hopenet now sees the primary 300W-LP solution of each prediction (|yaw| <= 90), not what was written
    prim = -Rotation.from_matrix(A300).as_euler("XYZ", degrees=True)
    e = np.abs(prim - gt[A].to_numpy()).mean(axis=0)
    assert np.allclose([h["pitch"], h["yaw"], h["roll"]], e, atol=1e-6)
    # as written in 300w_lp, nothing is re-expressed and the numbers are the peer's (golden)
    rep2 = _report(GOLD / "pred.csv", GOLD / "gt.csv", "300w_lp")
    assert rep2["protocols"]["hopenet"]["re_expressed"] == {"pred": 0, "gt": 0}
    assert rep2["protocols"]["hopenet"]["pitch"] != pytest.approx(h["pitch"])
