"""draw and augment read every storage kind the same way as angles (rotation vectors, quaternions)."""

import cv2
import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from conftest import canonical_A, hpe

F = np.diag([1.0, -1, -1])


def test_draw_rotvec_equals_draw_angles(tmp_path):
    rng = np.random.default_rng(2)
    pyr = np.column_stack([rng.uniform(-60, 60, 4), rng.uniform(-80, 80, 4), rng.uniform(-60, 60, 4)])
    base = pd.DataFrame({"image": [f"{i}.png" for i in range(4)], "tdx": 64.0, "tdy": 64.0, "size": 50.0})
    base.assign(pitch=pyr[:, 0], yaw=pyr[:, 1], roll=pyr[:, 2]).to_csv(tmp_path / "ang.csv", index=False)
    rv = Rotation.from_matrix(F @ canonical_A(pyr) @ F).as_rotvec()  # img2pose rotation vectors
    base.assign(rx=rv[:, 0], ry=rv[:, 1], rz=rv[:, 2]).to_csv(tmp_path / "rv.csv", index=False)
    assert hpe("draw", tmp_path / "ang.csv", "-o", tmp_path / "a", "--canvas", "128x128", "-q").exit_code == 0
    res = hpe("draw", tmp_path / "rv.csv", "-o", tmp_path / "b", "--canvas", "128x128", "--system", "img2pose", "-q")
    assert res.exit_code == 0, res.output
    for i in range(4):
        a = cv2.imread(str(tmp_path / "a" / f"{i}.png")).astype(int)
        b = cv2.imread(str(tmp_path / "b" / f"{i}.png")).astype(int)
        assert np.abs(a - b).max() == 0


def test_augment_quaternion_input(tmp_path):
    rng = np.random.default_rng(5)
    pyr = np.column_stack([rng.uniform(-60, 60, 6), rng.uniform(-80, 80, 6), rng.uniform(-60, 60, 6)])
    A = canonical_A(pyr)
    sysf = tmp_path / "q.toml"
    sysf.write_text('name = "q_canonical"\nstorage_kind = "quaternion"\n')
    q = Rotation.from_matrix(A).as_quat()[:, [3, 0, 1, 2]]
    pd.DataFrame({"id": range(6), "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]}).to_csv(
        tmp_path / "q.csv", index=False
    )
    pd.DataFrame({"id": range(6), "pitch": pyr[:, 0], "yaw": pyr[:, 1], "roll": pyr[:, 2]}).to_csv(
        tmp_path / "a.csv", index=False
    )
    res = hpe(
        "augment",
        tmp_path / "q.csv",
        "-o",
        tmp_path / "qo.csv",
        "--system",
        sysf,
        "--hflip",
        "--image-size",
        "450",
        "450",
        "-q",
    )
    assert res.exit_code == 0, res.output
    res = hpe("augment", tmp_path / "a.csv", "-o", tmp_path / "ao.csv", "--hflip", "--image-size", "450", "450", "-q")
    assert res.exit_code == 0, res.output
    mq = pd.read_csv(tmp_path / "qo.csv")[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy()
    ma = pd.read_csv(tmp_path / "ao.csv")[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy()
    assert np.abs(mq - ma).max() < 1e-12
