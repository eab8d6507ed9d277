"""hpe convert on every storage kind, input and output (SciPy as the oracle)."""

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import canonical_A, hpe

F = np.diag([1.0, -1, -1])


@pytest.fixture
def pyr():
    rng = np.random.default_rng(4)
    return np.column_stack([rng.uniform(-170, 170, 200), rng.uniform(-89, 89, 200), rng.uniform(-170, 170, 200)])


def test_rotvec_in_300wlp_out(tmp_path, pyr):
    A = canonical_A(pyr)
    rv = Rotation.from_matrix(F @ A @ F).as_rotvec()  # img2pose's rotation vectors
    src = tmp_path / "rv.csv"
    pd.DataFrame({"img": range(len(rv)), "rx": rv[:, 0], "ry": rv[:, 1], "rz": rv[:, 2], "tz": 1.0}).to_csv(
        src, index=False
    )
    out = tmp_path / "o.csv"
    res = hpe("convert", src, "-o", out, "--from", "img2pose", "--to", "300w_lp", "-q")
    assert res.exit_code == 0, res.output
    got = pd.read_csv(out)
    assert {"img", "rx", "ry", "rz", "tz"} <= set(got.columns)  # other columns kept
    assert np.abs(got[["pitch", "yaw", "roll"]].to_numpy() - pyr).max() < 1e-9


def test_300wlp_to_quaternion_user_system(tmp_path, pyr):
    sysf = tmp_path / "quat.toml"
    sysf.write_text(
        'name = "my_quat"\nstorage_kind = "quaternion"\nquaternion_order = "xyzw"\n'
        'frame = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]\n[columns]\nqx = "QX"\nqy = "QY"\nqz = "QZ"\nqw = "QW"\n'
    )
    src = tmp_path / "l.csv"
    pd.DataFrame({"pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2]}).to_csv(src, index=False)
    out = tmp_path / "q.parquet"
    res = hpe("convert", src, "-o", out, "--from", "300w_lp", "--to", sysf, "-q")
    assert res.exit_code == 0, res.output
    got = pd.read_parquet(out)
    q = got[["QX", "QY", "QZ", "QW"]].to_numpy()
    assert (q[:, 3] >= 0).all()
    ref = Rotation.from_matrix(F @ canonical_A(pyr) @ F).as_quat()
    ref *= np.where(ref[:, 3] < 0, -1, 1)[:, None]
    assert np.abs(q - ref).max() < 1e-12
    # and back: reading the quaternion columns (the angle columns removed)
    back_in = tmp_path / "q_only.csv"
    got[["QX", "QY", "QZ", "QW"]].to_csv(back_in, index=False)
    res = hpe("convert", back_in, "-o", tmp_path / "b.csv", "--from", sysf, "--to", "300w_lp", "-q")
    assert res.exit_code == 0, res.output
    assert np.abs(pd.read_csv(tmp_path / "b.csv")[["pitch", "yaw", "roll"]].to_numpy() - pyr).max() < 1e-9


def test_6d_and_4x4_and_named_angle_columns(tmp_path, pyr):
    src = tmp_path / "l.csv"
    pd.DataFrame({"pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2]}).to_csv(src, index=False)
    A = canonical_A(pyr)
    for target, cols, ref in [
        (
            "6drepnet_6d",
            [f"sixd_{i}" for i in range(6)],
            np.concatenate([A.transpose(0, 2, 1)[:, :, 0], A.transpose(0, 2, 1)[:, :, 1]], 1),
        ),
        ("mediapipe", [f"m{i}{j}" for i in range(3) for j in range(3)], A.reshape(-1, 9)),
        (
            "trinet",
            ["left_x", "left_y", "left_z", "down_x", "down_y", "down_z", "front_x", "front_y", "front_z"],
            (np.diag([1.0, -1, 1]) @ A @ np.diag([1.0, -1, 1])).transpose(0, 2, 1).reshape(-1, 9),
        ),
        ("openface", ["pose_Rx", "pose_Ry", "pose_Rz"], Rotation.from_matrix(F @ A @ F).as_euler("XYZ")),
    ]:
        out = tmp_path / f"{target}.csv"
        res = hpe("convert", src, "-o", out, "--from", "300w_lp", "--to", target, "--overwrite", "-q")
        assert res.exit_code == 0, res.output
        got = pd.read_csv(out)[cols].to_numpy()
        assert np.abs(got - ref).max() < 1e-9, target


def test_bad_quaternion_and_missing_columns(tmp_path):
    sysf = tmp_path / "q.toml"
    sysf.write_text('name = "q"\nstorage_kind = "quaternion"\n')
    src = tmp_path / "q.csv"
    pd.DataFrame({"qw": [1.0, 2.0, 0.0], "qx": [0, 0, 0.0], "qy": [0, 0, 0.0], "qz": [0, 0, 0.0]}).to_csv(
        src, index=False
    )
    rej = tmp_path / "rej.csv"
    res = hpe("convert", src, "-o", tmp_path / "o.csv", "--from", sysf, "--to", "300w_lp", "--rejects", rej, "-q")
    assert res.exit_code == 0, res.output
    reasons = pd.read_csv(rej)["reason"].tolist()
    assert reasons == ["not a unit quaternion (norm differs from 1 by more than 1e-3)"] * 2
    bad = tmp_path / "x.csv"
    pd.DataFrame({"a": [1.0]}).to_csv(bad, index=False)
    res = hpe("convert", bad, "-o", tmp_path / "o2.csv", "--from", "img2pose", "--to", "300w_lp", "-q")
    assert res.exit_code == 1 and "img2pose's rotvec columns rx,ry,rz" in res.output


def test_decoder_columns(tmp_path, realdata):
    out = tmp_path / "d.csv"
    res = hpe(
        "convert",
        realdata / "aflw2000_prnet",
        "-o",
        out,
        "--from",
        "300w_lp",
        "--to",
        "3ddfa_v2",
        "--decoder",
        "3ddfa_v2",
        "-q",
    )
    assert res.exit_code == 0, res.output
    got = pd.read_csv(out)
    # no AFLW2000 sample is past 86.4 deg of yaw: matrix2angle prints the exact 3ddfa_v2 angles
    assert (
        np.abs(
            got[["decoder_pitch", "decoder_yaw", "decoder_roll"]].to_numpy() - got[["pitch", "yaw", "roll"]].to_numpy()
        ).max()
        < 1e-9
    )
    assert got["decoder_ok"].all()
