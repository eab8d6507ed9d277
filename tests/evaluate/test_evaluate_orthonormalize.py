"""``hpe evaluate --orthonormalize``: raw network matrices (TriNet's vectors) projected to the nearest rotation."""

import json

import numpy as np
import pandas as pd
import scipy.linalg
from scipy.spatial.transform import Rotation

from conftest import hpe

COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]


def _files(tmp_path, n=60, seed=3):
    rng = np.random.default_rng(seed)
    G = Rotation.random(n, random_state=seed).as_matrix()
    P = Rotation.from_rotvec(rng.normal(0, 0.1, (n, 3))).as_matrix() @ G
    M = P + rng.normal(0, 0.05, P.shape)  # a network's raw, non-orthonormal output
    M[0] = P[0] @ np.diag([1.0, 1.0, -1.0])  # a reflection: det -1
    M[1] = P[1]  # already a rotation
    names = [f"img{i:03d}.jpg" for i in range(n)]
    gt = pd.DataFrame(G.reshape(n, 9), columns=COLS).assign(image=names)
    pred = pd.DataFrame(M.reshape(n, 9), columns=COLS).assign(image=names).sample(frac=1.0, random_state=1)
    gt.to_csv(tmp_path / "gt.csv", index=False)
    pred.to_csv(tmp_path / "pred.csv", index=False)
    return G, M


def _run(tmp_path, *args):
    return hpe(
        "evaluate",
        tmp_path / "pred.csv",
        tmp_path / "gt.csv",
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--columns",
        "matrix",
        "-q",
        *args,
    )


def test_off_by_default_rows_rejected_with_reason(tmp_path):
    _files(tmp_path)
    r = _run(tmp_path)
    assert r.exit_code == 1 and "pred.csv" in r.output and "not a rotation" in r.output
    assert len(r.output.strip().splitlines()) == 1
    r = _run(tmp_path, "--rejects", tmp_path / "rej.csv", "--json", tmp_path / "rep.json")
    assert r.exit_code == 0, r.output
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert (rej["side"] == "pred").all() and rej["reason"].str.contains("not a rotation").all()
    assert json.loads((tmp_path / "rep.json").read_text())["n"]["invalid"] == len(rej) == 59


def test_orthonormalize_matches_polar_decomposition(tmp_path):
    G, M = _files(tmp_path)
    out = tmp_path / "rows.parquet"
    r = _run(tmp_path, "--orthonormalize", "-o", out, "--json", tmp_path / "rep.json")
    assert r.exit_code == 0, r.output
    rep = json.loads((tmp_path / "rep.json").read_text())
    assert rep["n"]["pairs"] == len(G) and rep["n"]["invalid"] == 0
    rows = pd.read_parquet(out)
    idx = rows["image"].str.slice(3, 6).astype(int).to_numpy()
    # oracle: the orthogonal polar factor (SciPy), with det fixed to +1 by flipping the smallest singular direction
    for k, i in enumerate(idx):
        U, _, Vt = scipy.linalg.svd(M[i])
        R = U @ np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))]) @ Vt
        if np.linalg.det(M[i]) > 0:
            R_polar, _ = scipy.linalg.polar(M[i])
            np.testing.assert_allclose(R, R_polar, atol=1e-9)
        assert abs(rows["pred_rotation_distance"].iloc[k] - np.linalg.norm(M[i] - R)) < 1e-9
        geo = np.degrees(Rotation.from_matrix(R @ G[i].T).magnitude())
        assert abs(rows["geodesic"].iloc[k] - geo) < 1e-6
    assert rows.loc[idx == 1, "pred_rotation_distance"].iloc[0] < 1e-9
    assert rows.loc[idx == 0, "pred_rotation_distance"].iloc[0] > 1.0  # the reflection is far from any rotation
