"""``--protocol directmhp`` runs the DirectMHP scorer its peer runs on the GT's dataset (hnuzhy/DirectMHP@a51b06b
utils/mae.py: ``_single`` for AFLW2000, 300W-LP, BIWI, split at |GT yaw| > 99; ``_v2`` for CMU Panoptic and
AGORA, split at 90) and says which; ``directmhp-single`` / ``directmhp-v2`` still name one explicitly."""

import json
from pathlib import Path
from types import SimpleNamespace

import pyarrow as pa
import pytest

from conftest import hpe
from hpe_cli.pipelines.evaluate.dataset import choose_directmhp, gt_dataset

AFLW = Path(__file__).resolve().parents[3] / "shared" / "realdata" / "aflw2000_prnet"


def _src(cols, dataset=False, system=None, path="labels.csv", meta=None):
    return SimpleNamespace(
        path=Path(path),
        dataset=dataset,
        system=system,
        columns=cols,
        schema=pa.schema([(c, pa.string()) for c in cols], metadata=meta),
    )


@pytest.mark.parametrize(
    "src, want",
    [
        (_src(["file", "pitch", "yaw", "roll"], True, "300w_lp", "/data/AFLW2000"), "directmhp-single"),
        (_src(["file", "pitch", "yaw", "roll"], True, "300w_lp", "/data/300W_LP"), "directmhp-single"),
        (_src(["file", "sequence", "frame", "pitch", "yaw", "roll"], True, "biwi", "/data/biwi"), "directmhp-single"),
        (_src(["sequence", "frame", "camera", "person_id", "image", "pitch", "yaw", "roll"]), "directmhp-v2"),
        (
            _src(["image", "pitch", "yaw", "roll"], meta={b"hpe:relabel": json.dumps({"source": "cmu_panoptic"})}),
            "directmhp-v2",
        ),
        (
            _src(["image", "pitch", "yaw", "roll"], meta={b"hpe:relabel": json.dumps({"source": "agora"})}),
            "directmhp-v2",
        ),
        (_src(["source", "row", "person", "image", "occlusion", "pitch", "yaw", "roll"]), "directmhp-v2"),
    ],
)
def test_variant_by_dataset(src, want):
    got, note = choose_directmhp(["hopenet", "directmhp"], src)
    assert got == ["hopenet", want] and want in note and gt_dataset(src)[0] in note


def test_unknown_dataset_keeps_v2_and_says_so():
    src = _src(["image", "pitch", "yaw", "roll"])
    got, note = choose_directmhp(["directmhp"], src)
    assert got == ["directmhp"] and "not recognised" in note and "> 90" in note
    assert choose_directmhp(["directmhp-single", "directmhp-v2"], src) == (["directmhp-single", "directmhp-v2"], None)
    # asking for the generic name and the variant it resolves to gives one entry
    mat = _src(["file"], True, "300w_lp", "/data/AFLW2000")
    assert choose_directmhp(["directmhp", "directmhp-single"], mat)[0] == ["directmhp-single"]


@pytest.mark.skipif(not AFLW.is_dir(), reason="shared data not available")
def test_cli_prints_the_choice_on_aflw2000(tmp_path):
    import pandas as pd

    from hpe_cli.datasets.mat import read_mat_dir

    gt = read_mat_dir(AFLW)
    pred = tmp_path / "pred.csv"
    pd.DataFrame({"image": gt["file"], "pitch": gt["pitch"] + 1, "yaw": gt["yaw"], "roll": gt["roll"]}).to_csv(
        pred, index=False
    )
    args = ["evaluate", str(pred), str(AFLW), "--pred-system", "300w_lp", "--gt-system", "300w_lp"]
    js = tmp_path / "r.json"
    r = hpe(*args + ["--protocol", "directmhp", "--json", str(js)])
    assert r.exit_code == 0, r.output
    assert "directmhp: GT is AFLW2000-3D / 300W-LP (.mat labels)" in r.output
    rep = json.loads(js.read_text())
    assert list(rep["protocols"]) == ["directmhp-single"]
    assert "mean_absolute_error_calculate_single" in rep["protocols"]["directmhp-single"]["source"]
    r = hpe(*args + ["--protocol", "directmhp-v2", "--json", str(js), "--overwrite"])
    assert r.exit_code == 0 and list(json.loads(js.read_text())["protocols"]) == ["directmhp-v2"]
