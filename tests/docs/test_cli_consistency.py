"""One spelling per idea across every command: names, metavars, types and help of the shared options."""

from __future__ import annotations

from pathlib import Path

import click
import pytest

from conftest import hpe
from hpe_cli.cli import options as opt
from hpe_cli.cli.main import COMMANDS, cli

ROOT = Path(__file__).resolve().parents[2]
NAMES = list(COMMANDS)
#: commands that read rows (a table, a dataset's files): each needs --rejects and --strict
ROW_READERS = [
    "convert",
    "audit",
    "draw",
    "augment",
    "evaluate",
    "export",
    "relabel-panoptic",
    "relabel-agora",
    "biwi",
    "infer",
    "view",
]
#: commands that read angle tables (degrees by default): each needs --radians
ANGLE_READERS = ["convert", "audit", "draw", "augment", "evaluate", "export", "infer", "view"]
#: commands that read no rows / no angle table, with why (a new command must be put in one list or the other)
NOT_ROW_READERS = {"systems": "lists the built-in systems"}
NOT_ANGLE_READERS = {
    "systems": "lists the built-in systems",
    "relabel-panoptic": "reads 3-D face landmarks, writes degrees",
    "relabel-agora": "reads SMPL-X fits, writes degrees",
    "biwi": "reads BIWI's own pose files (matrices, or .bin angles always in degrees)",
}
#: known gaps, each naming who closes it: checked when the option is there, skipped while it is not
REJECTS_GAPS: dict = {}
RADIANS_GAPS: dict = {}
#: the one --radians whose help differs, and why: infer's flag pair also sets the units of the user's code, whose
#: default is radians (--radians/--degrees)
RADIANS_OWN_HELP = {"infer": "its --radians/--degrees also sets the units of --callable/--decoder code"}


def command(name):
    return cli.get_command(None, name)


def options(name):
    return {o: p for p in command(name).params if isinstance(p, click.Option) for o in p.opts + p.secondary_opts}


def shared(option):
    return {n: options(n)[option] for n in NAMES if option in options(n)}


def test_every_command_has_examples_in_help():
    for name in NAMES:
        assert "Examples:" in (command(name).help or ""), name


def test_every_command_is_classified():
    """A new command must say whether it reads rows and angle tables (so the checks below cannot miss it)."""
    assert sorted(ROW_READERS + list(NOT_ROW_READERS)) == sorted(NAMES)
    assert sorted(ANGLE_READERS + list(NOT_ANGLE_READERS)) == sorted(NAMES)
    assert set(REJECTS_GAPS) <= set(ROW_READERS) and set(RADIANS_GAPS) <= set(ANGLE_READERS)


@pytest.mark.parametrize("name", ROW_READERS)
def test_rejects_and_strict_on_every_row_reader(name):
    o = options(name)
    if name in REJECTS_GAPS and not ("--rejects" in o and "--strict" in o):
        pytest.skip(f"known gap: {REJECTS_GAPS[name]}")
    assert "--rejects" in o and "--strict" in o
    assert o["--strict"].is_flag and not o["--strict"].secondary_opts
    assert isinstance(o["--rejects"].type, click.Path)  # and the same help everywhere (test below)


@pytest.mark.parametrize("name", ANGLE_READERS)
def test_radians_on_every_angle_reader(name):
    o = options(name)
    if name in RADIANS_GAPS and "--radians" not in o:
        pytest.skip(f"known gap: {RADIANS_GAPS[name]}")
    assert "--radians" in o and o["--radians"].is_flag, name
    if name not in RADIANS_GAPS and name not in RADIANS_OWN_HELP:
        assert o["--radians"].help == opt.RADIANS_HELP, name


def test_rejects_help_is_the_same_everywhere():
    helps = {n: p.help for n, p in shared("--rejects").items()}
    assert len(set(helps.values())) == 1, helps
    assert isinstance(next(iter(shared("--rejects").values())).type, click.Path)


def test_image_size_is_wxh_everywhere():
    found = shared("--image-size")
    assert set(found) >= {"augment", "draw", "relabel-agora"}
    for name, p in found.items():
        assert isinstance(p.type, opt.ImageSize) and p.metavar == "WxH" and p.nargs == 1, name
    for name in NAMES:
        assert "--canvas" not in options(name), name


def test_radians_is_the_one_angle_unit_option():
    for name in NAMES:
        assert "--units" not in options(name), name
    helps = {n: p.help for n, p in shared("--radians").items() if n not in RADIANS_GAPS and n not in RADIANS_OWN_HELP}
    assert set(helps.values()) == {opt.RADIANS_HELP}, helps
    assert set(shared("--radians")) <= set(ANGLE_READERS)  # no --radians on a command that reads no angles
    for name, p in shared("--radians").items():
        assert p.is_flag, name


def test_max_rmse_is_centimetres_everywhere():
    found = shared("--max-rmse")
    assert set(found) == {"relabel-panoptic", "relabel-agora"}
    for name, p in found.items():
        assert isinstance(p.type, opt.Length) and p.metavar == "CM" and "centimetres" in p.help, name
    assert found["relabel-panoptic"].type.unit == "cm"
    assert found["relabel-agora"].type.unit == "m"  # AGORA's pipeline works in metres: converted at the door


@pytest.mark.parametrize(
    "value,unit,expected",
    [
        ("2", "cm", 2.0),
        ("2cm", "cm", 2.0),
        ("0.02m", "cm", 2.0),
        ("20mm", "cm", 2.0),
        ("2", "m", 0.02),
        ("0.02m", "m", 0.02),
        ("3.5 cm", "m", 0.035),
        ("inf", "m", float("inf")),
        ("INF", "cm", float("inf")),
    ],
)
def test_length_units(value, unit, expected):
    assert opt.Length(unit=unit).convert(value, None, None) == pytest.approx(expected)


@pytest.mark.parametrize("value", ["-1", "2km", "abc", "nan", "", "2 c m"])
def test_length_rejects_bad_values(value):
    with pytest.raises(click.BadParameter):
        opt.Length().convert(value, None, None)


@pytest.mark.parametrize(
    "option",
    [
        "--overwrite",
        "-q",
        "-v",
        "--columns-map",
        "--delimiter",
        "--no-header",
        "--names",
        "--input-format",
        "--batch-size",
        "--threads",
    ],
)
def test_shared_option_help_is_identical(option):
    found = shared(option)
    assert len(found) >= 2
    helps = {n: p.help for n, p in found.items() if not (option == "-v" and n == "systems")}
    metas = {n: (p.metavar, type(p.type).__name__) for n, p in found.items() if not (option == "-v" and n == "systems")}
    assert len(set(helps.values())) == 1, helps
    assert len(set(metas.values())) == 1, metas


def test_system_options_use_the_system_type():
    for name in NAMES:
        for o, p in options(name).items():
            if o in ("--system", "--from", "--to", "--pred-system", "--gt-system"):
                assert p.type is opt.SYSTEM, (name, o)


def test_deprecated_image_size_forms_warn_and_work(tmp_path):
    out = tmp_path / "a.parquet"
    r = hpe("augment", ROOT / "sample_data/aflw2000", "-o", out, "--image-size", "450", "450", "--hflip", "-q")
    assert r.exit_code == 0, r.output
    assert "deprecated" in r.stderr and "--image-size 450x450" in r.stderr
    r2 = hpe(
        "augment",
        ROOT / "sample_data/aflw2000",
        "-o",
        tmp_path / "b.parquet",
        "--image-size",
        "450x450",
        "--hflip",
        "-q",
    )
    assert r2.exit_code == 0 and "deprecated" not in r2.stderr
    assert out.read_bytes()[-200:] != b"" and (tmp_path / "b.parquet").stat().st_size == out.stat().st_size


def test_deprecated_canvas_warns_and_draws(tmp_path):
    r = hpe(
        "draw", ROOT / "sample_data/labels_300wlp.csv", "-o", tmp_path / "c", "--canvas", "64x48", "--limit", "2", "-q"
    )
    assert r.exit_code == 0, r.output
    assert "--canvas is deprecated" in r.stderr
    import cv2

    img = cv2.imread(str(next((tmp_path / "c").iterdir())))
    assert img.shape[:2] == (48, 64)


def test_deprecated_units_maps_to_radians(tmp_path):
    fx = f"{ROOT}/tests/fixtures/conventions/sixdrepnet.py:get_R"
    r = hpe("infer", "--callable", fx, "--args", "pitch,yaw,roll", "--units", "rad")
    assert r.exit_code == 0 and "--units rad is deprecated; use --radians" in r.stderr and "6drepnet" in r.stdout
    r = hpe("infer", "--callable", fx, "--args", "pitch,yaw,roll", "--units", "deg")
    assert r.exit_code == 1 and "use --degrees" in r.stderr
    r = hpe("infer", "--callable", fx, "--args", "pitch,yaw,roll", "--units", "grad")
    assert r.exit_code == 2


def test_max_rmse_suffix_reaches_the_pipeline(tmp_path):
    a = hpe(
        "relabel-panoptic",
        ROOT / "sample_data/panoptic_160906_pizza1",
        "-o",
        tmp_path / "a.parquet",
        "--rejects",
        tmp_path / "ra.csv",
        "--max-rmse",
        "0.01m",
    )
    b = hpe(
        "relabel-panoptic",
        ROOT / "sample_data/panoptic_160906_pizza1",
        "-o",
        tmp_path / "b.parquet",
        "--rejects",
        tmp_path / "rb.csv",
        "--max-rmse",
        "1",
    )
    assert a.exit_code == 0 and b.exit_code == 0
    assert "(--max-rmse 1)" in a.stderr and "(--max-rmse 1)" in b.stderr
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()


def test_agora_max_rmse_in_centimetres(tmp_path):
    pkl = ROOT / "tests/data/agora/validation_0_withjv.pkl"
    a = hpe("relabel-agora", pkl, "-o", tmp_path / "a.parquet", "--rejects", tmp_path / "ra.csv", "--max-rmse", "2")
    b = hpe("relabel-agora", pkl, "-o", tmp_path / "b.parquet", "--rejects", tmp_path / "rb.csv", "--max-rmse", "0.02m")
    assert a.exit_code == 0 and b.exit_code == 0, a.output
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()
    assert "fit RMSE (cm)" in a.stderr and "(--max-rmse 2)" in a.stderr
    c = hpe("relabel-agora", pkl, "-o", tmp_path / "c.parquet", "--rejects", tmp_path / "rc.csv", "--max-rmse", "0.02")
    assert c.exit_code == 0 and "write 0.02m for metres" in c.stderr


def test_augment_radians_equals_degrees(tmp_path):
    import numpy as np
    import pandas as pd

    df = pd.read_csv(ROOT / "sample_data/labels_300wlp.csv")
    rad = df.copy()
    rad[["pitch", "yaw", "roll"]] = np.radians(df[["pitch", "yaw", "roll"]])
    df.to_csv(tmp_path / "deg.csv", index=False)
    rad.to_csv(tmp_path / "rad.csv", index=False)
    a = hpe("augment", tmp_path / "deg.csv", "-o", tmp_path / "a.parquet", "--image-size", "512x512", "--rotate", 20)
    b = hpe(
        "augment",
        tmp_path / "rad.csv",
        "-o",
        tmp_path / "b.parquet",
        "--image-size",
        "512x512",
        "--rotate",
        20,
        "--radians",
    )
    assert a.exit_code == 0 and b.exit_code == 0, b.output
    A, B = pd.read_parquet(tmp_path / "a.parquet"), pd.read_parquet(tmp_path / "b.parquet")
    cols = [f"r{i}{j}" for i in range(3) for j in range(3)]
    np.testing.assert_allclose(B[cols].to_numpy(), A[cols].to_numpy(), atol=1e-12)
    np.testing.assert_allclose(
        B[["pitch", "yaw", "roll"]].to_numpy(), A[["pitch", "yaw", "roll"]].to_numpy(), atol=1e-9
    )


def test_system_list_options_use_the_system_list_type():
    for name in NAMES:
        for o, p in options(name).items():
            if o == "--also-in":
                assert p.type is opt.SYSTEMS and p.metavar == "SYSTEM[,SYSTEM...]", (name, o)
