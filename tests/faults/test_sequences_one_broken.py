"""Several Panoptic sequences in one run, one of them broken: the run fails with one line naming the broken
file (face file, calibration, empty face folder), for one process and for workers; nothing is written.
(Decision: a sequence that cannot be read is an input error, not rows in the rejects: a dataset silently
missing a sequence is worse than no dataset. Faces and views that cannot be labelled stay rejects.)"""

from __future__ import annotations

import os
import shutil

import pytest

from conftest import hpe

from .conftest import SYNTH, check_failed


def _root(tmp_path):
    root = tmp_path / "root"
    for s in ("seqA", "seqB", "seqC"):
        (root / s / "hdFace3d").mkdir(parents=True)
        shutil.copy(SYNTH / f"calibration_{SYNTH.name}.json", root / s / f"calibration_{s}.json")
        for f in (SYNTH / "hdFace3d").glob("*.json"):
            shutil.copy(f, root / s / "hdFace3d" / f.name)
    return root


def _break(root, how):
    if how == "face":
        bad = root / "seqB" / "hdFace3d" / "faceRecon3D_hd00000103.json"
        bad.write_text('{"version": 0.7, "people": [')
    elif how == "calibration":
        bad = root / "seqC" / "calibration_seqC.json"
        bad.write_text('{"cameras": [{"name": null}]}')
    else:
        bad = root / "seqC"
        shutil.rmtree(bad / "hdFace3d")
        (bad / "hdFace3d").mkdir()
    return bad


@pytest.mark.parametrize("how,workers", [("face", "1"), ("face", "2"), ("calibration", "1"), ("empty", "1")])
def test_one_broken_sequence_fails_the_run_naming_it(tmp_path, how, workers):
    root = _root(tmp_path)
    bad = _break(root, how)
    out = tmp_path / "out"
    out.mkdir()
    res = hpe("relabel-panoptic", root, "-o", out / "o.parquet", "--rejects", out / "r.csv", "--workers", workers, "-q")
    check_failed(res, must_name=bad)
    assert os.listdir(out) == []
