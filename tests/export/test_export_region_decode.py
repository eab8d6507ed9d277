"""``hpe export`` crops decode only the part of each JPEG frame that its heads need, to the same bytes.

The real CMU Panoptic HD frames, relabelled; the export is run twice, once with the rectangle decoder
(``_hpe_jpeg``) and once with it switched off (OpenCV decodes whole frames): every file written is the same,
byte for byte, and the rectangle decoder did decode the crops.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import hpe
from hpe_cli.io import jpeg
from hpe_cli.pipelines.export import workers

REALDATA = Path(__file__).resolve().parents[3] / "shared" / "realdata"
PIZZA = REALDATA / "panoptic_160906_pizza1"


@pytest.fixture(scope="module")
def pizza(tmp_path_factory):
    if not (PIZZA / "hdImgs").is_dir():
        pytest.skip("no real Panoptic frames")
    out = tmp_path_factory.mktemp("pizza") / "pizza.parquet"
    r = hpe("relabel-panoptic", PIZZA, "-o", out, "--cameras", "00_00,00_08,00_15,00_23", "-q")
    assert r.exit_code == 0, r.output
    return out


def _files(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("layout", ["whenet", "6drepnet", "fsanet"])
def test_crops_are_the_same_bytes_with_and_without_the_rectangle_decoder(tmp_path, pizza, monkeypatch, layout):
    pytest.importorskip("_hpe_jpeg")
    bands = []
    real = workers.decode_band

    def counted(*args, **kwargs):
        got = real(*args, **kwargs)
        bands.append(got is not None)
        return got

    monkeypatch.setattr(workers, "decode_band", counted)
    extra = ["--form", "crops"] if layout == "6drepnet" else []

    def export(name, state):
        monkeypatch.setattr(jpeg, "_STATE", state)
        out = tmp_path / name
        r = hpe("export", pizza, "-o", out, "--layout", layout, "--images", PIZZA, "-q",
                "--rejects", tmp_path / f"{name}.csv", *extra)  # fmt: skip
        assert r.exit_code == 0, r.output
        return out

    fast = export("fast", {})
    assert bands and all(bands)  # every frame was decoded over its heads only
    whole = export("whole", {"region": None})  # as without _hpe_jpeg: whole frames
    a, b = _files(fast), _files(whole)
    assert json.loads(a.pop("export.json"))["exported"] == json.loads(b.pop("export.json"))["exported"] > 0
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()  # frames missing: rejects
    assert a.keys() == b.keys() and len(a) >= 2
    for k in a:
        if k.endswith(".npz"):  # a zip: its members' dates may differ, the arrays may not
            with np.load(fast / k) as x, np.load(whole / k) as y:
                assert x.files == y.files and all(np.array_equal(x[f], y[f]) for f in x.files), k
        else:
            assert a[k] == b[k], k
