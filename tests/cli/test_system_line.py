"""The ``labels of FILE: system S (origin)`` line: printed once per input, and it says when the user's option
agrees with the file's own system (rather than ignoring the option)."""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import hpe

ROOT = Path(__file__).resolve().parents[2]
AFLW = ROOT / "sample_data" / "aflw2000"
LABELS = ROOT / "sample_data" / "labels_300wlp.csv"


@pytest.mark.parametrize(
    "args",
    [
        ["draw", AFLW, "-o", "{tmp}/d", "--style", "cube"],
        ["draw", LABELS, "-o", "{tmp}/d", "--image-size", "450x450"],
        ["convert", AFLW, "-o", "{tmp}/x.csv", "--from", "300w_lp", "--to", "6drepnet"],
        ["augment", AFLW, "-o", "{tmp}/a.parquet", "--image-size", "450x450", "--hflip"],
        ["audit", LABELS],
        ["export", AFLW, "-o", "{tmp}/e", "--layout", "fsanet"],
    ],
)
def test_system_line_printed_once(args, tmp_path):
    r = hpe(*[str(a).replace("{tmp}", str(tmp_path)) for a in args])
    assert r.exit_code == 0, r.output
    lines = [line for line in r.stderr.splitlines() if line.startswith("labels of ")]
    assert len(lines) == len(set(lines)) <= 1, r.stderr


@pytest.mark.parametrize(
    "args,option",
    [
        (["draw", AFLW, "-o", "{tmp}/d", "--system", "300w_lp"], "--system"),
        (["convert", AFLW, "-o", "{tmp}/x.csv", "--from", "300w_lp", "--to", "6drepnet"], "--from"),
    ],
)
def test_an_agreeing_option_is_named(args, option, tmp_path):
    r = hpe(*[str(a).replace("{tmp}", str(tmp_path)) for a in args])
    assert r.exit_code == 0, r.output
    assert f"labels of {AFLW}: system 300w_lp (file metadata; {option} agrees)" in r.stderr, r.stderr
    without = [a for a in args if a not in (option, "300w_lp")]
    r = hpe(*[str(a).replace("{tmp}", str(tmp_path)).replace("/d", "/d2").replace("x.csv", "y.csv") for a in without])
    if r.exit_code == 0:
        assert f"labels of {AFLW}: system 300w_lp (file metadata)\n" in r.stderr and "agrees" not in r.stderr
