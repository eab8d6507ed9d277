"""Every row rejected, with --rejects: the run exits 1 and writes no main output, but the rejects file the user
asked for (the one output that says why) is written, with every row and its reason. Without --rejects, or with
--strict, nothing is written (issue 35)."""

from __future__ import annotations

import pandas as pd
import pytest

from conftest import hpe


@pytest.fixture
def bad_table(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("image,pitch,yaw,roll\na.jpg,x,1,2\nb.jpg,,1,2\nc.jpg,nan,1,2\n")
    return path


@pytest.fixture
def missing_images(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("image,pitch,yaw,roll\na.jpg,1,1,2\nb.jpg,3,1,2\n")
    return path


def _cases(tmp_path, bad_table, missing_images):
    return {
        "augment": (["augment", bad_table, "-o", tmp_path / "out.csv", "--image-size", "100x100", "--hflip"], 3),
        "augment-images": (
            [
                "augment",
                missing_images,
                "-o",
                tmp_path / "out.csv",
                "--hflip",
                "--images",
                tmp_path,
                "--out-images",
                tmp_path / "imgs",
            ],
            2,
        ),
        "draw": (["draw", missing_images, "-o", tmp_path / "out"], 2),
    }


@pytest.mark.parametrize("case", ["augment", "augment-images", "draw"])
def test_all_rejected_still_writes_the_rejects_file(case, tmp_path, bad_table, missing_images):
    args, n = _cases(tmp_path, bad_table, missing_images)[case]
    before = {p.name for p in tmp_path.iterdir()}
    rej = tmp_path / "rej.csv"
    r = hpe(*args, "--rejects", rej)
    assert r.exit_code == 1, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and f"every row's reason -> {rej}" in lines[0]
    assert rej.is_file()
    frame = pd.read_csv(rej)
    assert len(frame) == n and frame["reason"].notna().all() and (frame["reason"] != "").all()
    after = {p.name for p in tmp_path.iterdir()}
    assert after - before == {"rej.csv"}, after - before  # no main output, no images folder, no temporaries


@pytest.mark.parametrize("case", ["augment", "draw"])
def test_without_rejects_or_with_strict_nothing_is_written(case, tmp_path, bad_table, missing_images):
    args, _ = _cases(tmp_path, bad_table, missing_images)[case]
    before = {p.name for p in tmp_path.iterdir()}
    assert hpe(*args).exit_code == 1
    assert hpe(*args, "--rejects", tmp_path / "rej.csv", "--strict").exit_code == 1
    assert {p.name for p in tmp_path.iterdir()} == before


def test_an_existing_rejects_file_needs_overwrite(tmp_path, bad_table, missing_images):
    args, _ = _cases(tmp_path, bad_table, missing_images)["augment"]
    rej = tmp_path / "rej.csv"
    rej.write_text("old\n")
    r = hpe(*args, "--rejects", rej)
    assert r.exit_code == 1 and "already exists" in r.output and rej.read_text() == "old\n"
    r = hpe(*args, "--rejects", rej, "--overwrite")
    assert r.exit_code == 1 and len(pd.read_csv(rej)) == 3


def test_draw_sets_unparseable_rows_aside_with_rejects(tmp_path):
    """draw read the whole table with the reader that stops at the first unparseable row, so with --rejects a
    non-numeric angle still ended the run; it is now a reject like in every other command."""
    src = tmp_path / "t.csv"
    src.write_text("image,pitch,yaw,roll\na.jpg,x,1,2\nb.jpg,3,1,2\n")
    rej = tmp_path / "rej.csv"
    r = hpe("draw", src, "-o", tmp_path / "d", "--image-size", "64x64", "--rejects", rej)
    assert r.exit_code == 0, r.output
    assert "rejected: 1 non-numeric value in pitch" in r.output
    frame = pd.read_csv(rej)
    assert frame["row"].tolist() == [2] and frame["reason"].tolist() == ["non-numeric value in pitch"]
    assert len(list((tmp_path / "d").iterdir())) == 1
    # without --rejects: the first such row is the error, nothing written
    r = hpe("draw", src, "-o", tmp_path / "d2", "--image-size", "64x64")
    assert r.exit_code == 1 and f"{src}: line 2: non-numeric value in pitch" in r.output
    assert not (tmp_path / "d2").exists()
    # every row unparseable: exit 1, the rejects file says why
    bad = tmp_path / "bad.csv"
    bad.write_text("image,pitch,yaw,roll\na.jpg,x,1,2\n")
    r = hpe("draw", bad, "-o", tmp_path / "d3", "--image-size", "64x64", "--rejects", tmp_path / "rej3.csv")
    assert r.exit_code == 1 and "every row's reason" in r.output
    assert len(pd.read_csv(tmp_path / "rej3.csv")) == 1 and not (tmp_path / "d3").exists()


def _export_table(path, pitch=("1", "3")):
    path.write_text(
        "image,pitch,yaw,roll,bbox_x,bbox_y,bbox_w,bbox_h\n"
        f"a.jpg,{pitch[0]},1,2,10,10,40,40\nb.jpg,{pitch[1]},1,2,10,10,40,40\n"
    )
    return path


@pytest.mark.parametrize(
    "pitch, first_reason",
    [(("1", "3"), "no image (file not found)"), (("x", ""), "unreadable row: non-numeric value in pitch")],
    ids=["no-image", "bad-labels"],
)
def test_export_with_every_label_rejected_still_writes_the_rejects_file(tmp_path, pitch, first_reason):
    """export: every label rejected before the pixels (bad labels) or by them (no image) -> exit 1, no export
    folder, and the rejects file with every row and its reason."""
    table = _export_table(tmp_path / "t.csv", pitch)
    before = {p.name for p in tmp_path.iterdir()}
    rej = tmp_path / "rej.csv"
    args = ["export", table, "-o", tmp_path / "out", "--layout", "fsanet", "--images", tmp_path, "--system", "300w_lp"]
    r = hpe(*args, "--rejects", rej)
    assert r.exit_code == 1, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: --layout fsanet: ") and f"-> {rej}" in lines[0], r.output
    frame = pd.read_csv(rej)
    assert frame["row"].tolist() == [2, 3] and frame["reason"].iloc[0] == first_reason
    assert {p.name for p in tmp_path.iterdir()} - before == {"rej.csv"}
    # without --rejects, or with --strict: nothing at all
    rej.unlink()
    assert hpe(*args).exit_code == 1
    assert hpe(*args, "--rejects", rej, "--strict").exit_code == 1
    assert {p.name for p in tmp_path.iterdir()} == before
