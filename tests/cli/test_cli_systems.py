"""hpe systems: every system with its four parts, in words and as data."""

import json

from conftest import hpe

BUILTINS = {"300w_lp", "whenet", "6drepnet", "3ddfa_v2", "scipy_zyx", "opencv"}


def test_text_listing():
    res = hpe("systems")
    assert res.exit_code == 0
    for name in BUILTINS:
        assert name in res.output
    for part in ("frame", "axes", "range", "order"):
        assert f"  {part}" in res.output


def test_json_listing_and_extra_file(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text(
        'name = "mine"\n'
        + "".join(f'[[turns]]\nangle = "{r}"\naxis = "{a}"\n' for r, a in [("yaw", "z"), ("pitch", "y"), ("roll", "x")])
    )
    res = hpe("systems", "--json", f)
    assert res.exit_code == 0
    data = {d["name"]: d for d in json.loads(res.output)}
    assert BUILTINS | {"mine"} <= set(data)
    d = data["6drepnet"]
    assert d["storage"] == "transposed" and d["sequence"] == "extrinsic" and len(d["turns"]) == 3
    assert set(d["in_words"]) >= {"frame", "axes", "range", "order"}


def test_top_level_help_fast_and_lists_commands():
    res = hpe("--help")
    assert res.exit_code == 0 and "convert" in res.output and "systems" in res.output and "Examples" in res.output


def test_verbose_shows_source_storage_frame_verification():
    res = hpe("systems", "--verbose")
    assert res.exit_code == 0, res.output
    block = res.output.split("\ntrinet\n")[1].split("\n\n")[0]
    assert "LEFT-HANDED" in block and "computeMAE.py" in block and "left_x" in block
    assert "  verified" in block and "  source" in block and "  example" in block
    for name in ("img2pose", "aflw", "openface", "mediapipe", "dad3dheads", "openvino_adas", "synhead", "6drepnet_6d"):
        assert f"\n{name}\n" in "\n" + res.output
    assert "documented, unverified on data" in res.output
    assert "rotation vector" in res.output and "6-D: matrix column 0 then column 1" in res.output


def test_bad_user_file_is_a_usage_error(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text(
        'name = "mine"\ngimbal_tol = -1\n'
        + "".join(f'[[turns]]\nangle = "{r}"\naxis = "{a}"\n' for r, a in [("yaw", "z"), ("pitch", "y"), ("roll", "x")])
    )
    res = hpe("convert", f, "-o", tmp_path / "o.csv", "--from", f, "--to", "300w_lp")
    assert res.exit_code == 2 and "gimbal_tol: expected a number in [0, 1)" in res.output and "got -1" in res.output


def test_systems_by_name_and_did_you_mean():
    """`hpe systems NAME`: only the named built-ins (any case); a misspelt name says which one was meant."""

    r = hpe("systems", "6DRepNet", "whenet")
    assert r.exit_code == 0, r.output
    heads = [line for line in r.output.splitlines() if line and not line.startswith(" ")]
    assert heads == ["6drepnet", "whenet"]
    r = hpe("systems", "300wlp")
    assert r.exit_code == 2 and "no built-in system '300wlp' (did you mean '300w_lp'?)" in r.output
    r = hpe("systems", "missing.toml")
    assert r.exit_code == 2 and "no file 'missing.toml'" in r.output
