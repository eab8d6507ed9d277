"""``DrawOptions`` / ``ViewOptions``: built alike by the commands and the Python API (same bytes), validated once
("expected X, got Y"); the audit's pictures read the audit's own opened table (no second system resolution)."""

from pathlib import Path

import pytest

import hpe_cli as hpe
from conftest import hpe as hpe_cmd
from hpe_cli.errors import HpeError
from hpe_cli.pipelines.draw import DrawOptions, WorstOptions, flagged_pictures
from hpe_cli.pipelines.view import ViewOptions

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data" / "aflw2000"  # 4 .mat files with their images


def _files(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    "args, options",
    [
        ([], {}),
        (["--style", "cube", "--annotate", "--system", "6drepnet"], {"style": "cube", "annotate": True}),
        (["--grid", "--grid-cols", "2", "--tile", "64"], {"grid": True, "grid_cols": 2, "tile": 64}),
    ],
)
def test_api_draw_file_writes_the_cli_bytes(tmp_path, args, options):
    res = hpe_cmd("draw", SAMPLE, "-o", tmp_path / "cli", "-q", *args)
    assert res.exit_code == 0, res.output
    system = "6drepnet" if "6drepnet" in args else None
    s = hpe.draw_file(SAMPLE, tmp_path / "api", system=system, **options)
    assert s["faces"] == 4 and s["images"] == 4
    cli_files, api_files = _files(tmp_path / "cli"), _files(tmp_path / "api")
    assert cli_files and cli_files == api_files


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: DrawOptions(style="box"), "style: expected one of axes, cube, got 'box'"),
        (lambda: DrawOptions(tile=8), "tile: expected an integer in [32, 2048], got 8"),
        (lambda: DrawOptions(grid_cols=0), "grid_cols: expected an integer in [1, 64], got 0"),
        (lambda: DrawOptions(worst=0), "worst: expected an integer >= 1, got 0"),
        (lambda: DrawOptions(length=-1.0), "length: expected a number of pixels > 0, got -1.0"),
        (lambda: DrawOptions(canvas=(640,)), "canvas: expected (width, height), got (640,)"),
        (lambda: DrawOptions(tdy_origin="middle"), "tdy_origin: expected one of auto, top, bottom, got 'middle'"),
        (lambda: WorstOptions(on_missing="ignore"), "on_missing: expected one of canvas, error, skip, got 'ignore'"),
        (lambda: ViewOptions(threads=0), "threads: expected an integer >= 1 or None, got 0"),
        (lambda: ViewOptions(use="rotvec"), "use: expected one of auto, angles, matrix, got 'rotvec'"),
        (lambda: ViewOptions(keys="image"), "keys: expected a list of column names, got 'image'"),
    ],
)
def test_options_are_checked_once(make, message):
    with pytest.raises(HpeError) as e:
        make()
    assert str(e.value) == message


def test_options_are_frozen_and_normalised():
    o = DrawOptions(canvas=[640, 480])
    assert o.canvas == (640, 480)
    with pytest.raises(AttributeError):
        o.style = "cube"
    assert ViewOptions(keys=["image", "person_id"], also_in=["6drepnet"]).keys == ("image", "person_id")


def test_flagged_pictures_read_the_audits_label_source(tmp_path, monkeypatch):
    """The pictures come from the LabelSource the audit opened: resolving the system again would fail here (the
    old second rule, io.columns.label_system, is gone)."""
    import hpe_cli.io.system_meta as system_meta
    from hpe_cli.io.label_source import open_labels

    labels = open_labels(SAMPLE)

    def again(*a, **k):
        raise AssertionError("the system was resolved a second time")

    monkeypatch.setattr(system_meta, "resolve_system", again)
    examples = {"near_gimbal": [{"row": 2}, {"row": 4}], "out_of_range": [{"row": 1}]}
    out = flagged_pictures(labels, examples, tmp_path / "plots")
    assert [p["path"] for p in out["pictures"]] == [
        "pictures/near_gimbal_1.png",
        "pictures/near_gimbal_2.png",
        "pictures/out_of_range_1.png",
    ]
    assert not out["missing"]
    assert all((tmp_path / "plots" / p["path"]).is_file() for p in out["pictures"])
    assert (
        out["pictures"][0]["caption"].startswith("near_gimbal: ") and "image00251.mat" in out["pictures"][0]["caption"]
    )


@pytest.mark.parametrize("command", ["draw", "view"])
def test_columns_angles_without_angle_columns_is_an_error(tmp_path, command):
    """``--columns angles`` on a table holding only r00..r22: one line naming the missing columns, exit 1 (the
    old reader read the absent columns as zeros and drew every face looking straight ahead)."""
    import pandas as pd

    R = hpe.get_system("300w_lp").from_angles([[10.0, 20.0, 30.0]])[0]
    row = {"image": "image00050.jpg", **{f"r{i}{j}": [R[i, j]] for i in range(3) for j in range(3)}}
    pd.DataFrame(row).to_csv(tmp_path / "m.csv", index=False)
    res = hpe_cmd(command, tmp_path / "m.csv", "-o", tmp_path / "out", "--images", SAMPLE, "--columns", "angles")
    assert res.exit_code == 1, res.output
    assert res.output.strip() == (
        f"Error: {tmp_path / 'm.csv'}: missing column(s) pitch, yaw, roll for --columns angles"
    )
    assert not (tmp_path / "out").exists()
