"""evaluate -> draw --worst --rejects on the real AFLW2000 sample: missing images listed with their reason (rows
numbered as the input numbers them), the rest drawn; every image missing exits 1 and writes nothing."""

import shutil
from pathlib import Path

import pandas as pd
import pytest

from conftest import hpe


@pytest.mark.parametrize("kind", ["parquet", "csv"])
def test_missing_images_are_rejects_the_rest_drawn(realdata, errors, tmp_path, kind):
    t = pd.read_parquet(errors)
    src = errors
    if kind == "csv":
        src = tmp_path / "errors.csv"
        t.to_csv(src, index=False)
    worst = t.sort_values("geodesic", ascending=False)["image"].tolist()[:5]
    imgs = tmp_path / "imgs"
    imgs.mkdir()
    for name in worst[1:4]:  # the worst and the 5th have no image
        for ext in (".jpg", ".mat"):
            shutil.copy(realdata / "aflw2000_prnet" / name.replace(".mat", ext), imgs)
    out = tmp_path / "worst"
    res = hpe("draw", src, "-o", out, "--images", imgs, "--worst", 5)
    assert res.exit_code == 1 and "image not found" in res.output and not out.exists()
    row0 = t.index[t["image"] == worst[0]][0]
    want_where = f"line {row0 + 2}" if kind == "csv" else f"row {row0 + 1}"
    assert f"{src}: {want_where}: image not found" in res.output, res.output
    res = hpe("draw", src, "-o", out, "--images", imgs, "--worst", 5, "--rejects", tmp_path / "rej.csv")
    assert res.exit_code == 0, res.output
    assert "rejected: 2 image not found" in res.output
    assert sorted(p.name for p in out.iterdir()) == [
        f"{k + 2:04d}_{Path(n).stem}.png" for k, n in enumerate(worst[1:4])
    ]
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert sorted(rej["image"]) == sorted([worst[0], worst[4]])
    assert all(r.startswith("image not found") for r in rej["reason"])
    rows = sorted(int(t.index[t["image"] == n][0]) for n in (worst[0], worst[4]))
    assert sorted(rej["row"]) == [r + (2 if kind == "csv" else 1) for r in rows]


def test_every_image_missing_exits_1(errors, tmp_path):
    res = hpe(
        "draw", errors, "-o", tmp_path / "w", "--images", tmp_path, "--worst", 3, "--rejects", tmp_path / "rej.csv"
    )
    assert res.exit_code == 1 and "nothing drawn: all 3 row(s) rejected" in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "w").exists()
    # the rejects file the user asked for is written all the same: it says why (issue 35)
    assert "every row's reason -> " in res.output
    assert len(pd.read_csv(tmp_path / "rej.csv")) == 3
