"""The top-level Python API (``import hpe_cli as hpe``): lazy, and the same answers as SciPy and the core."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import hpe_cli as hpe
from conftest import canonical_A
from hpe_cli.errors import HpeError

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("torch", "torchvision", "pandas", "pyarrow", "scipy", "matplotlib", "cv2")


def _python(code):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, env=env, check=True
    )


def test_import_is_lazy():
    out = _python("import sys, hpe_cli; print(sorted(m for m in sys.modules if m.split('.')[0] in %r))" % (HEAVY,))
    assert out.stdout.strip() == "[]"
    # -X importtime: every module the import loaded, with its cumulative time in microseconds
    loaded = [line.split("|")[-1].strip() for line in out.stderr.splitlines() if line.startswith("import time:")]
    assert "hpe_cli" in loaded and not any(m.split(".")[0] in HEAVY for m in loaded)
    total = next(int(line.split("|")[1]) for line in out.stderr.splitlines() if line.rstrip().endswith("| hpe_cli"))
    assert total < 200_000  # 0.2 s: generous for a loaded CI machine; it is ~1 ms
    # the lazy names resolve on first use
    out = _python("import hpe_cli as hpe; print(hpe.RotationSystem.__name__, hpe.Conversion.__name__)")
    assert out.stdout.split() == ["RotationSystem", "Conversion"]


def test_dir_and_missing_attribute():
    assert {"convert", "read_labels", "geodesic", "RotationSystem"} <= set(dir(hpe))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        hpe.nope


def test_get_system_and_systems():
    assert hpe.get_system("biwi") is hpe.systems()["biwi"]
    assert set(hpe.systems()) >= {"300w_lp", "6drepnet", "biwi", "opencv", "whenet", "scipy_zyx", "3ddfa_v2"}


def test_convert_every_storage_kind_against_scipy():
    rng = np.random.default_rng(0)
    pyr = rng.uniform([-80, -89, -80], [80, 89, 80], (50, 3))
    A = canonical_A(pyr)  # SPEC's 300W-LP matrix, written out independently
    ref = hpe.convert(pyr, "300w_lp", "scipy_zyx")
    assert np.abs(ref.canonical - A).max() < 1e-12
    # scipy_zyx is SciPy's intrinsic ZYX, (yaw, pitch, roll) in its own frame
    back = Rotation.from_matrix(ref.matrix).as_euler("ZYX", degrees=True)
    assert np.abs(back[:, [1, 0, 2]] - ref.primary).max() < 1e-9
    R = hpe.get_system("300w_lp").from_angles(pyr)
    rot = Rotation.from_matrix(R)
    for values, storage, kw in [
        (R, None, {}),
        (rot.as_rotvec(), "rotvec", {}),
        (rot.as_quat()[:, [3, 0, 1, 2]], None, {}),
        (rot.as_quat(), "quaternion", {"quaternion_order": "xyzw"}),
    ]:
        c = hpe.convert(values, "300w_lp", "scipy_zyx", storage=storage, **kw)
        assert np.abs(c.matrix - ref.matrix).max() < 1e-12
    # 6-D: 6DRepNet's network output for the 300W-LP label (20, -50, 15) (the example in 6drepnet_6d.toml)
    d6 = [0.620885153, 0.166365675, 0.766044443, -0.496285454, 0.839862101, 0.21984631]
    c6 = hpe.convert([d6], "6drepnet_6d", "300w_lp")
    assert np.abs(c6.primary - [[20, -50, 15]]).max() < 1e-6
    assert (
        np.abs(hpe.convert(np.array(d6) * 3.0, "6drepnet_6d", "300w_lp", storage="6d").primary - c6.primary).max()
        < 1e-9
    )
    with pytest.raises(ValueError, match="unit quaternion"):
        hpe.convert([[2.0, 0, 0, 0]], "300w_lp", "biwi")
    one = hpe.convert(pyr[0], "300w_lp", "scipy_zyx")
    assert one.primary.shape == (1, 3) and np.allclose(one.primary, ref.primary[:1])


def test_convert_errors():
    with pytest.raises(ValueError, match="storage='angles' or storage='matrix'"):
        hpe.convert(np.eye(3), "300w_lp", "biwi")
    with pytest.raises(ValueError, match="expected storage in"):
        hpe.convert([[1, 2, 3]], "300w_lp", "biwi", storage="euler")
    with pytest.raises(ValueError, match=r"expected rotvec values of shape \(N, 3\)"):
        hpe.convert(np.zeros((2, 4)), "300w_lp", "biwi", storage="rotvec")


def test_read_and_write_labels(tmp_path, realdata):
    df = {"file": ["a.jpg", "b.jpg"], "pitch": [1.0, 2.0], "yaw": [3.0, 4.0], "roll": [5.0, 6.0]}
    import dataclasses

    custom = dataclasses.replace(hpe.get_system("6drepnet"), name="my_system")
    p = hpe.write_labels(df, tmp_path / "l.parquet", system=custom)
    table, system = hpe.read_labels(p)
    assert system == custom  # the whole definition comes back, not just the name
    for name, builtin in hpe.systems().items():  # every built-in system survives the metadata round trip
        hpe.write_labels(df, tmp_path / f"{name}.parquet", system=builtin)
        assert hpe.read_labels(tmp_path / f"{name}.parquet").system == builtin
    assert table["file"].tolist() == ["a.jpg", "b.jpg"] and table["roll"].tolist() == [5.0, 6.0]
    with pytest.raises(HpeError, match="already exists"):
        hpe.write_labels(df, p)
    hpe.write_labels(table, p, system="biwi", overwrite=True)
    assert hpe.read_labels(p).system.name == "biwi"
    c = hpe.write_labels(df, tmp_path / "l.csv")
    assert hpe.read_labels(c).system is None and hpe.read_labels(c, system="opencv").system.name == "opencv"
    labels = hpe.read_labels(realdata / "aflw2000_prnet")
    assert labels.system.name == "300w_lp" and len(labels.table) == 16
    with pytest.raises(HpeError, match="no such file"):
        hpe.read_labels(tmp_path / "missing.parquet")


def test_audit_geodesic_draw():
    r = hpe.audit(np.array([[[1.0, 0, 0], [0, 1, 0], [0, 0, 2]]]), "300w_lp")
    assert r["not_rotation"].tolist() == [True]
    assert hpe.audit([[0, 95, 0]], "300w_lp")["out_of_range"].tolist() == [True]
    R1 = Rotation.random(20, random_state=1).as_matrix()
    R2 = Rotation.random(20, random_state=2).as_matrix()
    ref = np.rad2deg((Rotation.from_matrix(R1).inv() * Rotation.from_matrix(R2)).magnitude())
    assert np.abs(hpe.geodesic(R1, R2) - ref).max() < 1e-9
    with pytest.raises(ValueError, match="system="):
        hpe.geodesic([0, 0, 0], [0, 1, 0])
    img = np.zeros((64, 64, 3), np.uint8)
    hpe.draw_axes(
        img, [[0.0, 90.0, 0.0]], (32, 32), 20, thickness=1
    )  # 300W-LP yaw 90: A[:, 2] = (-1, 0, 0), the nose line points to image left
    assert img[32, 14, 0] > 100 and img[32, 50].max() == 0  # blue channel, left of the centre only


def test_evaluate_forwards_to_the_metrics(monkeypatch):
    rng = np.random.default_rng(5)
    gt = rng.uniform(-60, 60, (40, 3))
    pred = gt + rng.normal(0, 3, gt.shape)
    r = hpe.evaluate(pred, gt, pred_system="300w_lp", gt_system="300w_lp")
    assert r["n"]["pairs"] == 40
    assert abs(r["metrics"]["geodesic"]["mean"] - hpe.geodesic(pred, gt, system="300w_lp").mean()) < 1e-9
    _test_evaluate_missing(monkeypatch)


def _test_evaluate_missing(monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "hpe_cli.metrics.evaluate" else real(name, *a)
    )
    with pytest.raises(NotImplementedError, match="hpe_cli.metrics.evaluate"):
        hpe.evaluate([[0, 0, 0]], [[0, 0, 0]], pred_system="300w_lp", gt_system="300w_lp")


def test_augment_wrappers_are_the_core_functions():
    from hpe_cli.geometry.augment import augment_batch

    pyr = np.array([[10.0, 20.0, 30.0], [-5.0, 60.0, 0.0]])
    a = hpe.augment_batch(pyr, op="mirror", angle=30.0, image_size=(100, 80))
    b = augment_batch(pyr, op="mirror", angle=30.0, image_size=(100, 80))
    assert np.array_equal(a.matrix, b.matrix)
    s = hpe.augment_sample(pyr[0], op="vflip", image_size=(100, 80))
    assert np.allclose(s.matrix, augment_batch(pyr[:1], op="vflip", image_size=(100, 80)).matrix[0])
