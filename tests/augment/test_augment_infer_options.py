"""AugmentOptions and InferOptions: validated once, built by the CLI and by the Python API alike (same outputs)."""

from __future__ import annotations

import dataclasses
import json
import shutil
import warnings

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

import hpe_cli as hpe
from conftest import hpe as hpe_cmd
from hpe_cli.errors import HpeError, UsageError
from hpe_cli.pipelines.augment import AugmentOptions, describe_op
from hpe_cli.pipelines.infer import InferOptions

MAT_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]


def run(*args):
    return hpe_cmd(*args, ok=True)


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"op": "spin"}, "op: expected one of hflip, vflip"),
        ({"op": "rotate"}, "angle: expected a number for rotate and mirror only"),
        ({"op": "hflip", "angle": 10.0}, "angle: expected a number for rotate and mirror only"),
        ({"op": "rotate", "angle": float("inf")}, "angle: expected a finite angle"),
        ({"op": "crop", "crop": (0, 0, 1.5, 4)}, "crop: expected 4 whole pixels"),
        ({"op": "crop", "crop": (0, 0, 0, 4)}, "crop: expected 4 whole pixels"),
        ({"op": "scale", "scale": 0.0}, "scale: expected a factor > 0"),
        ({"op": "hflip", "scheme": "ibug69"}, "scheme: expected one of auto"),
        ({"op": "hflip", "border": "mirror"}, "border: expected one of constant"),
        ({"op": "hflip", "jpeg_quality": 0}, "jpeg_quality: expected 1..100"),
        ({"op": "hflip", "image_size": (0, 10)}, "image_size: expected"),
    ],
)
def test_augment_options_refuse_bad_settings(kw, match):
    with pytest.raises(UsageError, match=match):
        AugmentOptions(**kw)


def test_augment_options_are_frozen_and_describe_the_op():
    opts = AugmentOptions("rotate", 30.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.op = "hflip"
    assert opts.description == "rotate 30 deg counter-clockwise"
    assert describe_op("crop", crop=(1, 2, 30, 40)) == "crop 30x40 at (1, 2)"
    assert AugmentOptions("hvflip").description == "hflip+vflip (rotation by 180)"


def test_augment_options_threads_and_the_deprecated_workers():
    """``threads`` is the spelling (as ``--threads`` and every other command's options); ``workers=`` still works,
    with a DeprecationWarning, once."""
    assert AugmentOptions("hflip", threads=3).threads == 3
    with pytest.warns(DeprecationWarning, match="use threads="):
        opts = AugmentOptions("hflip", workers=2)
    assert opts.threads == 2 and opts.workers is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert dataclasses.replace(opts, batch_size=7).threads == 2
    with pytest.raises(UsageError, match="threads: expected an integer >= 1"):
        AugmentOptions("hflip", threads=0)


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"roles": ("pitch", "yaw", "yaw")}, "roles: expected the three roles"),
        ({"angle_columns": (["pitch", "yaw"], ["a", "b"])}, "angle_columns: expected the three roles"),
        ({"matrix": tuple("abcdefgh")}, "matrix: expected 9 columns"),
        ({"rotations": ("rotvec", ("rx", "ry"))}, "rotations: expected"),
        ({"rotations": ("euler", ("a", "b", "c"))}, "rotations: expected"),
        ({"samples": 8}, "samples: expected 16..100000"),
        ({"timeout": float("nan")}, "timeout: expected a positive finite number"),
        ({"tol": 0.0}, "tol: expected a number > 0"),
        ({"units": "grad"}, "units: expected one of"),
        ({"packed": True}, "packed: applies to a callable"),
    ],
)
def test_infer_options_refuse_bad_settings(kw, match):
    with pytest.raises(UsageError, match=match):
        InferOptions(**kw)


def _labels(tmp_path, n=30):
    rng = np.random.default_rng(5)
    pyr = np.c_[rng.uniform(-80, 80, n), rng.uniform(-170, 170, n), rng.uniform(-80, 80, n)]
    df = pd.DataFrame(pyr, columns=["pitch", "yaw", "roll"])
    df["lm0_x"], df["lm0_y"] = rng.uniform(0, 63, n), rng.uniform(0, 47, n)
    df["bbox_x"], df["bbox_y"], df["bbox_w"], df["bbox_h"] = 10.0, 8.0, 30.0, 28.0
    path = tmp_path / "labels.csv"
    df.to_csv(path, index=False)
    return path


@pytest.mark.parametrize("flags, op, angle", [(["--rotate", "25"], "rotate", 25.0), (["--hflip"], "hflip", None)])
def test_augment_file_writes_what_the_command_writes(tmp_path, flags, op, angle):
    path = _labels(tmp_path)
    cli_out, api_out = tmp_path / "cli.parquet", tmp_path / "api.parquet"
    run("augment", path, "-o", cli_out, "--image-size", "64x48", "--landmarks", "none", *flags, "-q")
    s = hpe.augment_file(path, api_out, op, angle, image_size=(64, 48), scheme="none")
    assert s["rows"] == s["written"] == 30 and s["system"] == "300w_lp"
    a, b = pq.read_table(cli_out), pq.read_table(api_out)
    assert a.equals(b) and a.schema.metadata == b.schema.metadata


def test_infer_system_gives_the_commands_report(tmp_path):
    rng = np.random.default_rng(9)
    pyr = np.c_[rng.uniform(-80, 80, 60), rng.uniform(-80, 80, 60), rng.uniform(-80, 80, 60)]
    # an independent oracle for the labels: SciPy's intrinsic ZYX (yaw about y, pitch about x, roll about z)
    R = Rotation.from_euler("ZYX", pyr[:, [1, 0, 2]], degrees=True).as_matrix()
    df = pd.DataFrame(pyr, columns=["pitch", "yaw", "roll"])
    df[MAT_COLS] = R.reshape(-1, 9)
    path = tmp_path / "t.csv"
    df.to_csv(path, index=False)
    report = tmp_path / "r.json"
    run("infer", path, "--json", report, "-q")
    api = hpe.infer_system(path)
    assert api == json.loads(report.read_text())
    assert api["fit"] == "exact" and api["best"] == "scipy_zyx"
    with pytest.raises(HpeError, match="expected exactly one of DATA and the code"):
        hpe.infer_system()


def test_augment_file_on_a_mat_folder_uses_its_images_as_the_command_does(realdata, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for s in ("image00050", "image00081"):
        for ext in (".mat", ".jpg"):
            shutil.copy(realdata / "aflw2000_prnet" / f"{s}{ext}", src / f"{s}{ext}")
    run("augment", src, "-o", tmp_path / "cli.parquet", "--out-images", tmp_path / "cli", "--rotate", "17", "-q")
    s = hpe.augment_file(src, tmp_path / "api.parquet", "rotate", 17.0, out_images=tmp_path / "api")
    assert s["written"] == s["images"] == s["mats"] == 2
    assert pq.read_table(tmp_path / "cli.parquet").equals(pq.read_table(tmp_path / "api.parquet"))
    for name in ("image00050.jpg", "image00081.jpg"):
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "api" / name).read_bytes()
    for name in ("image00050.mat", "image00081.mat"):  # past the header, whose text holds the creation time
        assert (tmp_path / "cli" / name).read_bytes()[128:] == (tmp_path / "api" / name).read_bytes()[128:]
    with pytest.raises(UsageError, match="--out-images needs --images"):
        hpe.augment_file(tmp_path / "api.parquet", tmp_path / "x.parquet", "hflip", out_images=tmp_path / "x")
