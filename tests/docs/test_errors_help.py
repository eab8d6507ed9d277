"""Errors that help: one-line usage errors, system names matched case-insensitively with "did you mean",
a --columns-map hint for capitalised or renamed angle columns, a warning for radians read as degrees."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import hpe, hpe_process
from hpe_cli.io.labels import columns_map_hint

ROOT = Path(__file__).resolve().parents[2]
LABELS = ROOT / "sample_data" / "labels_300wlp.csv"


@pytest.mark.parametrize(
    "args",
    [
        ["convert", LABELS, "-o", "x.csv", "--from", "300wlp", "--to", "6drepnet"],
        ["convert", LABELS, "-o", "x.csv", "--frm", "300w_lp"],
        ["draw", LABELS, "-o", "d", "--image-size", "640x"],
        ["augment", LABELS, "-o", "x.csv", "--hflip"],
        ["relabel-panoptic", ROOT / "sample_data" / "panoptic_synth", "-o", "x.parquet", "--max-rmse", "2km"],
        ["conver"],
        ["--bogus"],
    ],
)
def test_usage_errors_are_one_line_exit_2(args, tmp_path):
    p = hpe_process(*args)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), p.stderr
    assert "Traceback" not in p.stderr and p.stdout == ""


def test_did_you_mean_300w_lp(tmp_path):
    p = hpe_process("convert", LABELS, "-o", tmp_path / "x.csv", "--from", "300wlp", "--to", "6drepnet")
    assert p.returncode == 2
    assert "unknown system '300wlp'; did you mean 300w_lp?" in p.stderr
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize(
    "typo,meant",
    [
        ("whennet", "whenet"),
        ("6d-repnet", "6drepnet"),
        ("300-W-LP", "300w_lp"),
        ("openvino", "openvino_adas"),
        ("scipy-zyx", "scipy_zyx"),
    ],
)
def test_did_you_mean_near_misses(typo, meant, tmp_path):
    r = hpe("convert", LABELS, "-o", tmp_path / "x.csv", "--from", "300w_lp", "--to", typo)
    assert r.exit_code == 2 and f"did you mean {meant}" in r.output, r.output


def test_no_suggestion_for_far_names(tmp_path):
    r = hpe("convert", LABELS, "-o", tmp_path / "x.csv", "--from", "300w_lp", "--to", "quaternion_thing")
    assert r.exit_code == 2 and "did you mean" not in r.output and "expected one of" in r.output


@pytest.mark.parametrize("name", ["300W_LP", "6DRepNet", "WHENET", "Scipy_ZYX"])
def test_system_names_case_insensitive(name, tmp_path):
    out = tmp_path / "x.parquet"
    r = hpe("convert", LABELS, "-o", out, "--from", name, "--to", "whenet", "-q")
    assert r.exit_code == 0, r.output
    ref = tmp_path / "ref.parquet"
    assert hpe("convert", LABELS, "-o", ref, "--from", name.lower(), "--to", "whenet", "-q").exit_code == 0
    a, b = pd.read_parquet(out), pd.read_parquet(ref)
    np.testing.assert_array_equal(a[["r00", "r11", "r22"]].to_numpy(), b[["r00", "r11", "r22"]].to_numpy())


def _capitalised(tmp_path, header=("Pitch", "Yaw", "Roll")):
    df = pd.read_csv(LABELS).rename(columns=dict(zip(("pitch", "yaw", "roll"), header)))
    path = tmp_path / "caps.csv"
    df.to_csv(path, index=False)
    return path


@pytest.mark.parametrize(
    "command", [["convert", "--from", "300w_lp", "--to", "6drepnet"], ["audit"], ["draw", "--image-size", "64x64"]]
)
def test_capitalised_columns_get_a_columns_map_hint(command, tmp_path):
    src = _capitalised(tmp_path)
    r = hpe(command[0], src, "-o", tmp_path / ("o.csv" if command[0] != "draw" else "d"), *command[1:])
    assert r.exit_code == 1
    assert "--columns-map pitch=Pitch,yaw=Yaw,roll=Roll" in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1
    # and the hint works as written
    if command[0] == "convert":
        ok = hpe(
            "convert",
            src,
            "-o",
            tmp_path / "ok.csv",
            *command[1:],
            "--columns-map",
            "pitch=Pitch,yaw=Yaw,roll=Roll",
            "-q",
        )
        assert ok.exit_code == 0, ok.output


@pytest.mark.parametrize(
    "columns,hint",
    [
        (["image", "Pitch", "Yaw", "Roll"], "; rename them with --columns-map pitch=Pitch,yaw=Yaw,roll=Roll"),
        (["PITCH", "YAW", "ROLL"], "; rename them with --columns-map pitch=PITCH,yaw=YAW,roll=ROLL"),
        (["head_pitch", "head_yaw", "roll"], "; rename them with --columns-map pitch=head_pitch,yaw=head_yaw"),
        (
            ["pitch_deg", "yaw_deg", "roll_deg"],
            "; rename them with --columns-map pitch=pitch_deg,yaw=yaw_deg,roll=roll_deg",
        ),
        (["image", "a", "b", "c"], ""),
        (["Pitch", "Yaw"], ""),  # roll nowhere: renaming two would not help
    ],
)
def test_columns_map_hint(columns, hint):
    assert columns_map_hint(columns) == hint


def _radians_file(tmp_path, n=40, suffix=".csv"):
    rng = np.random.default_rng(1)
    df = pd.DataFrame(
        {
            "image": [f"{i}.jpg" for i in range(n)],
            "pitch": rng.uniform(-1, 1, n),
            "yaw": rng.uniform(-3, 3, n),
            "roll": rng.uniform(-0.5, 0.5, n),
        }
    )
    path = tmp_path / f"rad{suffix}"
    (df.to_csv(path, index=False) if suffix == ".csv" else df.to_parquet(path))
    return path


@pytest.mark.parametrize(
    "command", [["convert", "--from", "300w_lp", "--to", "6drepnet"], ["audit"], ["evaluate-self"]]
)
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_radians_read_as_degrees_warn(command, suffix, tmp_path):
    src = _radians_file(tmp_path, suffix=suffix)
    if command[0] == "evaluate-self":
        r = hpe("evaluate", src, src, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--key", "image")
    else:
        r = hpe(command[0], src, "-o", tmp_path / "o.csv", *command[1:])
    assert r.exit_code == 0, r.output
    assert "read as degrees is within +-pi" in r.stderr and "add --radians" in r.stderr
    if command[0] != "evaluate-self":
        again = hpe(command[0], src, "-o", tmp_path / "o2.csv", *command[1:], "--radians")
        assert again.exit_code == 0 and "+-pi" not in again.stderr


def test_degrees_do_not_warn(tmp_path):
    r = hpe("convert", LABELS, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "6drepnet")
    assert r.exit_code == 0 and "+-pi" not in r.stderr


def test_a_handful_of_small_angles_do_not_warn(tmp_path):
    src = _radians_file(tmp_path, n=5)
    r = hpe("convert", src, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "6drepnet")
    assert r.exit_code == 0 and "+-pi" not in r.stderr


@pytest.mark.parametrize(
    "command",
    [
        ["convert", "--from", "300w_lp", "--to", "6drepnet"],
        ["audit"],
        ["draw", "--image-size", "500x500"],
        ["augment", "--image-size", "500x500", "--hflip"],
        ["evaluate-self"],
    ],
)
def test_degrees_read_as_radians_warn(command, tmp_path):
    """The mirror of the warning above: --radians on angles up to 170 (degrees) warns, naming the largest value."""
    if command[0] == "evaluate-self":
        args = ["evaluate", LABELS, LABELS, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--radians"]
    else:
        out = tmp_path / ("d" if command[0] == "draw" else "o.csv")
        args = [command[0], LABELS, "-o", out, *command[1:], "--radians"]
    r = hpe(*args)
    assert r.exit_code == 0, r.output
    assert "read as radians (--radians) reaches |value| 170" in r.stderr and "drop --radians" in r.stderr
    assert r.stderr.count("read as radians") == 1
    without = hpe(*[a for a in args if a != "--radians"], *(["--overwrite"] if command[0] != "evaluate-self" else []))
    assert "read as radians" not in without.stderr


def test_radians_within_a_turn_do_not_warn(tmp_path):
    src = _radians_file(tmp_path)
    r = hpe("convert", src, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "6drepnet", "--radians")
    assert r.exit_code == 0 and "read as radians" not in r.stderr and "+-pi" not in r.stderr
