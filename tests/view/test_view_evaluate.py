"""The angle ``hpe view`` shows between two label sets is ``hpe evaluate``'s per-row geodesic error, row by row
(both pages built from the same files; the page keeps 0.001 degree), and it agrees with SciPy's rotation
distance between the two poses."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import hpe

from .conftest import AFLW, PIZZA, PRED, page_data


def _evaluate_rows(tmp_path, pred, gt, *extra):
    out = tmp_path / "rows.csv"
    r = hpe("evaluate", pred, gt, "-o", out, "-q", *extra)
    assert r.exit_code == 0, r.output
    return pd.read_csv(out)


@pytest.mark.skipif(not (AFLW.is_dir() and PRED.is_file()), reason="shared data not available")
def test_aflw_angle_is_evaluate_geodesic(tmp_path):
    from scipy.spatial.transform import Rotation

    pred = tmp_path / "shuffled.csv"
    pd.read_csv(PRED).sample(frac=1.0, random_state=3).to_csv(pred, index=False)  # joined by key, not by order
    page = tmp_path / "page"
    r = hpe("view", AFLW, pred, "-o", page, "--other-system", "300w_lp", "-q")
    assert r.exit_code == 0, r.output
    data = page_data(page)
    ev = _evaluate_rows(tmp_path, pred, AFLW, "--pred-system", "300w_lp")
    names = [f"image{int(s[5:10]):05d}.jpg" for s in sorted(p.name for p in AFLW.glob("*.mat"))]
    geo = ev.set_index("image").loc[names, "geodesic"].to_numpy()
    angle = np.array(data["num"]["angle"], dtype=float)
    assert np.allclose(angle, geo, atol=6e-4), np.abs(angle - geo).max()
    assert angle.max() > 90  # the sample's 180-degree turn is there
    # SciPy: the angle of A_pred A_gt^T, with the 300W-LP matrix A = Rx(p).T Ry(y).T Rz(r).T
    gt = np.array([data["num"][k] for k in ("pitch", "yaw", "roll")]).T
    pr = pd.read_csv(pred).assign(image=lambda d: d.image.str.replace(".mat", ".jpg")).set_index("image").loc[names]

    def rot(pyr):
        return Rotation.from_euler("XYZ", -np.asarray(pyr, float), degrees=True)  # Rx(-p) Ry(-y) Rz(-r)

    ref = np.degrees((rot(pr[["pitch", "yaw", "roll"]].to_numpy()) * rot(gt).inv()).magnitude())
    assert np.allclose(angle, ref, atol=2e-3)


@pytest.mark.skipif(not PIZZA.is_dir(), reason="../shared/realdata is not available")
def test_pizza_corrected_vs_legacy_angle_is_evaluate_geodesic(tmp_path):
    corr, legacy = tmp_path / "c.parquet", tmp_path / "l.parquet"
    for out, extra in ((corr, []), (legacy, ["--legacy-whenet"])):
        assert hpe("relabel-panoptic", PIZZA, "-o", out, "-q", *extra).exit_code == 0
    page = tmp_path / "page"
    r = hpe("view", corr, legacy, "-o", page, "--images", PIZZA, "--rejects", tmp_path / "rej.csv", "-q")
    assert r.exit_code == 0, r.output
    data = page_data(page)
    ev = _evaluate_rows(tmp_path, legacy, corr, "--key", "image,person_id", "--rejects", tmp_path / "ev_rej.csv")
    c = pd.read_parquet(corr)[["image", "person_id"]]
    merged = c.merge(ev[["image", "person_id", "geodesic"]], on=["image", "person_id"], how="left")
    angle = np.array([np.nan if v is None else v for v in data["num"]["angle"]], dtype=float)
    has = merged["geodesic"].notna().to_numpy()
    assert has.sum() == len(pd.read_parquet(legacy))  # every legacy row is a corrected row
    assert np.array_equal(np.isfinite(angle), has)  # rows the legacy rule dropped have no angle
    assert np.allclose(angle[has], merged["geodesic"].to_numpy()[has], atol=6e-4)
    other = data["cat"]["other"]
    assert sum(other["values"][k] == "no row in OTHER" for k in other["codes"]) == (~has).sum()
