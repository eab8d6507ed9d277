"""hpe convert, end to end with CliRunner: formats, real .mat files, bad input, exit codes."""

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from conftest import canonical_A, hpe
from hpe_cli.io import LABEL_COLS, MATRIX_COLS

T = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)


@pytest.fixture
def labels(tmp_path):
    rng = np.random.default_rng(0)
    n = 500
    df = pd.DataFrame(
        {
            "image": [f"img{i}.jpg" for i in range(n)],
            "pitch": rng.uniform(-179, 179, n),
            "yaw": rng.uniform(-90, 90, n),
            "roll": rng.uniform(-179, 179, n),
            "score": rng.random(n),
        }
    )
    path = tmp_path / "labels.csv"
    df.to_csv(path, index=False)
    return path, df


def test_csv_to_parquet_scipy_oracle(tmp_path, labels):
    path, df = labels
    out = tmp_path / "out.parquet"
    res = hpe("convert", path, "-o", out, "--from", "300w_lp", "--to", "scipy_zyx", "-q")
    assert res.exit_code == 0, res.output
    table = pq.read_table(out)
    got = table.to_pandas()
    assert list(got.columns) == ["image", "score"] + LABEL_COLS
    assert got["image"].tolist() == df["image"].tolist()
    A = canonical_A(df[["pitch", "yaw", "roll"]].to_numpy())
    R_s = T @ A @ T.T
    assert np.abs(got[MATRIX_COLS].to_numpy().reshape(-1, 3, 3) - R_s).max() < 1e-12
    ypr = Rotation.from_matrix(R_s).as_euler("ZYX", degrees=True)
    assert np.abs(got[["yaw", "pitch", "roll"]].to_numpy() - ypr).max() < 1e-9
    # the second solution rebuilds the same rotation
    R2 = Rotation.from_euler("ZYX", got[["yaw_2", "pitch_2", "roll_2"]].to_numpy(), degrees=True).as_matrix()
    assert np.abs(R2 - R_s).max() < 1e-12
    assert got["roundtrip_err"].max() < 1e-13
    meta = table.schema.metadata
    assert meta[b"hpe:system"] == b"scipy_zyx" and b"turns" in meta[b"hpe:system_definition"]


def test_matrix_input_and_back(tmp_path, labels):
    path, df = labels
    mid = tmp_path / "m.parquet"
    assert hpe("convert", path, "-o", mid, "--from", "300w_lp", "--to", "6drepnet", "-q").exit_code == 0
    mats = pd.read_parquet(mid)[["image"] + MATRIX_COLS]
    only_m = tmp_path / "only_m.csv"
    mats.to_csv(only_m, index=False)
    back = tmp_path / "back.csv"
    res = hpe("convert", only_m, "-o", back, "--from", "6drepnet", "--to", "300w_lp", "-q")
    assert res.exit_code == 0, res.output
    got = pd.read_csv(back)
    A = canonical_A(df[["pitch", "yaw", "roll"]].to_numpy())
    assert np.abs(got[MATRIX_COLS].to_numpy().reshape(-1, 3, 3) - A).max() < 1e-12
    ok = np.abs(df["yaw"]) < 89.9  # input was already solution 1 of 300w_lp
    assert (
        np.abs(got.loc[ok, ["pitch", "yaw", "roll"]].to_numpy() - df.loc[ok, ["pitch", "yaw", "roll"]].to_numpy()).max()
        < 1e-9
    )


def test_radians_and_custom_toml(tmp_path):
    sysfile = tmp_path / "mine.toml"
    sysfile.write_text(
        'name = "mine"\nsequence = "extrinsic"\n'
        + "".join(
            f'[[turns]]\nangle = "{r}"\naxis = "{a}"\nhand = "right"\n'
            for r, a in [("roll", "z"), ("yaw", "x"), ("pitch", "y")]
        )
    )
    df = pd.DataFrame({"pitch": [0.1, -0.5], "yaw": [0.3, 1.2], "roll": [-0.2, 2.0]})
    src = tmp_path / "rad.csv"
    df.to_csv(src, index=False)
    out = tmp_path / "o.csv"
    res = hpe("convert", src, "-o", out, "--from", "300w_lp", "--to", sysfile, "--radians", "-q")
    assert res.exit_code == 0, res.output
    got = pd.read_csv(out)
    A = canonical_A(np.rad2deg(df.to_numpy()))
    # extrinsic z(roll), x(yaw), y(pitch) right-handed = SciPy lowercase "zxy" with (roll, yaw, pitch)
    R = Rotation.from_euler("zxy", got[["roll", "yaw", "pitch"]].to_numpy(), degrees=True).as_matrix()
    assert np.abs(R - A).max() < 1e-12


def test_real_mat_folder(tmp_path, realdata):
    out = tmp_path / "aflw.csv"
    res = hpe("convert", realdata / "aflw2000_prnet", "-o", out, "--from", "300w_lp", "--to", "300w_lp", "-q")
    assert res.exit_code == 0, res.output
    got = pd.read_csv(out).set_index("file")
    assert len(got) == 16
    row = got.loc["image00050.mat"]
    assert np.allclose(row[["pitch", "yaw", "roll"]].to_numpy(float), [-4.66, 0.94, 5.64], atol=0.005)
    assert np.allclose(row[["tdx", "tdy"]].to_numpy(float), [229.71, 209.54], atol=0.01)
    assert not got["gimbal_lock"].any() and got["roundtrip_err"].max() < 1e-13


def test_rejects_file_and_fail_without_it(tmp_path):
    df = pd.DataFrame(
        {"id": range(5), "pitch": [1, 2, np.nan, 4, 5], "yaw": ["1", "x", "3", "4", "inf"], "roll": [0, 0, 0, 0, 0]}
    )
    src = tmp_path / "bad.csv"
    df.to_csv(src, index=False)
    out = tmp_path / "o.parquet"
    res = hpe("convert", src, "-o", out, "--from", "300w_lp", "--to", "whenet")
    assert res.exit_code == 1
    assert res.output.strip().count("\n") == 0 and "bad.csv: line 3: non-numeric value in yaw; 3 row(s)" in res.output
    assert "Traceback" not in res.output and not out.exists()
    assert not list(tmp_path.glob(".*tmp"))
    rej = tmp_path / "rej.csv"
    res = hpe("convert", src, "-o", out, "--from", "300w_lp", "--to", "whenet", "--rejects", rej, "-q")
    assert res.exit_code == 0, res.output
    r = pd.read_csv(rej)
    assert r["row"].tolist() == [3, 4, 6]
    assert r["reason"].tolist() == ["non-numeric value in yaw", "missing value in pitch", "non-finite value in yaw"]
    assert pd.read_parquet(out)["id"].tolist() == [0, 3]


def test_not_rotation_matrix(tmp_path):
    m = np.stack([np.eye(3), np.diag([1.0, 1, -1]), 2 * np.eye(3)]).reshape(3, 9)
    src = tmp_path / "m.csv"
    pd.DataFrame(m, columns=MATRIX_COLS).to_csv(src, index=False)
    res = hpe("convert", src, "-o", tmp_path / "o.csv", "--from", "opencv", "--to", "300w_lp")
    assert res.exit_code == 1 and "line 3: not a rotation" in res.output
    res = hpe(
        "convert", src, "-o", tmp_path / "o.csv", "--from", "opencv", "--to", "300w_lp", "--rejects", tmp_path / "r.csv"
    )
    assert res.exit_code == 0
    assert pd.read_csv(tmp_path / "r.csv")["row"].tolist() == [3, 4]
    # opencv identity = F A F with A = diag(1,-1,-1) @ I @ diag(1,-1,-1) = I
    assert np.allclose(pd.read_csv(tmp_path / "o.csv")[["pitch", "yaw", "roll"]].to_numpy(), 0)


def test_overwrite_and_usage_errors(tmp_path, labels):
    path, _ = labels
    out = tmp_path / "o.csv"
    assert hpe("convert", path, "-o", out, "--from", "300w_lp", "--to", "whenet", "-q").exit_code == 0
    before = out.read_bytes()
    res = hpe("convert", path, "-o", out, "--from", "300w_lp", "--to", "6drepnet")
    assert res.exit_code == 1 and "--overwrite" in res.output and out.read_bytes() == before
    assert hpe("convert", path, "-o", out, "--from", "300w_lp", "--to", "6drepnet", "--overwrite", "-q").exit_code == 0
    res = hpe("convert", path, "-o", out, "--from", "hopenet", "--to", "6drepnet")
    assert res.exit_code == 2 and "300w_lp" in res.output and "scipy_zyx" in res.output
    res = hpe("convert", path, "-o", tmp_path / "o.txt", "--from", "300w_lp", "--to", "6drepnet")
    assert res.exit_code == 1 and "expected an output ending in .parquet or .csv" in res.output


@pytest.mark.parametrize(
    "content,msg",
    [("", "empty file"), ("a,b\n1,2\n", "missing column(s) pitch, yaw, roll"), ("pitch,yaw,roll\n", "empty table")],
)
def test_bad_files(tmp_path, content, msg):
    src = tmp_path / "in.csv"
    src.write_text(content)
    res = hpe("convert", src, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "whenet")
    assert res.exit_code == 1 and msg in res.output and str(src) in res.output, res.output
    assert not (tmp_path / "o.csv").exists()


def test_truncated_mat(tmp_path, realdata):
    d = tmp_path / "mats"
    d.mkdir()
    raw = (realdata / "aflw2000_prnet" / "image00050.mat").read_bytes()
    (d / "cut.mat").write_bytes(raw[: len(raw) // 3])
    res = hpe("convert", d, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "whenet")
    assert res.exit_code == 1 and "cut.mat" in res.output and "Traceback" not in res.output


def test_streams_batches_and_input_untouched(tmp_path, labels):
    path, df = labels
    before = path.read_bytes()
    out = tmp_path / "o.parquet"
    res = hpe("convert", path, "-o", out, "--from", "300w_lp", "--to", "3ddfa_v2", "--batch-size", "64", "-q")
    assert res.exit_code == 0
    assert len(pd.read_parquet(out)) == len(df) and path.read_bytes() == before


def test_help_has_examples():
    res = hpe("convert", "--help")
    assert res.exit_code == 0 and "Examples:" in res.output and "hpe convert" in res.output


def test_biwi_archive_and_pose_txt(tmp_path, realdata):
    out = tmp_path / "biwi.parquet"
    res = hpe("convert", realdata / "biwi" / "db_annotations.tgz", "-o", out, "--from", "biwi", "--to", "300w_lp", "-q")
    assert res.exit_code == 0, res.output
    got = pd.read_parquet(out)
    assert len(got) == 15677 and got["roundtrip_err"].max() < 1e-13
    out2 = tmp_path / "f3.csv"
    assert (
        hpe("convert", realdata / "biwi" / "hpdb", "-o", out2, "--from", "biwi", "--to", "300w_lp", "-q").exit_code == 0
    )
    row = pd.read_csv(out2).iloc[0]
    # PROVENANCE §4: Hopenet's reader (R.T, negated yaw/roll) gives (+7.61, 3.29, -1.57) for frame 3
    assert np.allclose(row[["pitch", "yaw", "roll"]].to_numpy(float), [7.61, 3.29, -1.57], atol=0.01)


def test_output_has_normal_permissions(tmp_path, labels):
    import os
    import stat

    path, _ = labels
    out = tmp_path / "o.csv"
    assert hpe("convert", path, "-o", out, "--from", "300w_lp", "--to", "whenet", "-q").exit_code == 0
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~umask


def test_duplicate_column_names_are_an_error(tmp_path):
    """Issue 9, class 1: 'yaw,pitch,yaw,roll,extra' used to convert the wrong column with exit 0."""
    src = tmp_path / "d.csv"
    src.write_text("yaw,pitch,yaw,roll,extra\n10,1,20,3,999\n")
    res = hpe("convert", src, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "300w_lp")
    assert res.exit_code == 1 and "d.csv: line 1: duplicate column name(s) 'yaw'" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "o.csv").exists()


def test_bad_rows_of_every_kind_go_to_rejects_with_their_lines(tmp_path):
    src = tmp_path / "b.csv"
    src.write_bytes(b'pitch,yaw,roll,image\n1,2,3,a\n1,2\n4,x,6,b\n7,8,9,caf\xe9\n1e300,0,0,c\n5,5,5,"q\n')
    rej = tmp_path / "r.csv"
    res = hpe(
        "convert", src, "-o", tmp_path / "o.parquet", "--from", "300w_lp", "--to", "whenet", "--rejects", rej, "-q"
    )
    assert res.exit_code == 0, res.output
    r = pd.read_csv(rej).sort_values("row")
    assert r["row"].tolist() == [3, 4, 5, 6, 7]
    assert r["reason"].tolist() == [
        "expected 4 fields, got 2",
        "non-numeric value in yaw",
        "undecodable bytes in image (not UTF-8)",
        "absurd angle in pitch: |value| > 1e+06 degrees",
        "unclosed quote",
    ]
    assert pd.read_parquet(tmp_path / "o.parquet")["image"].tolist() == ["a"]
