"""relabel-panoptic, relabel-agora and biwi: the Python API and the command build the same options object and
run the same pipeline, so they write the same bytes (labels and rejects)."""

from __future__ import annotations

from pathlib import Path

import pytest

import hpe_cli as hpe
from conftest import hpe as hpe_cmd
from hpe_cli.pipelines.biwi import BiwiOptions
from hpe_cli.pipelines.relabel import FormatSystemError, RelabelAgoraOptions, RelabelPanopticOptions

ROOT = Path(__file__).resolve().parents[2]
PIZZA = ROOT / "sample_data" / "panoptic_160906_pizza1"
AGORA = ROOT / "tests" / "data" / "agora" / "validation_0_withjv.pkl"
BIWI = ROOT / ".." / "shared" / "realdata" / "biwi" / "hpdb"


def run(*args):
    return hpe_cmd(*args, ok=True)


@pytest.mark.parametrize("name, fmt", [("labels.parquet", "table"), ("train.json", "coco")])
def test_relabel_panoptic(tmp_path, name, fmt):
    run(
        "relabel-panoptic",
        PIZZA,
        "-o",
        tmp_path / f"cli_{name}",
        "--rejects",
        tmp_path / "cli_r.parquet",
        "--min-change",
        "5",
        "-q",
    )
    got = hpe.relabel_panoptic(
        PIZZA, tmp_path / f"api_{name}", fmt=fmt, min_change=5, rejects=tmp_path / "api_r.parquet"
    )
    assert (tmp_path / f"api_{name}").read_bytes() == (tmp_path / f"cli_{name}").read_bytes()
    assert (tmp_path / "api_r.parquet").read_bytes() == (tmp_path / "cli_r.parquet").read_bytes()
    assert got.stats.labelled + sum(got.stats.view_reasons.values()) == got.stats.views


def test_relabel_agora(tmp_path):
    run(
        "relabel-agora",
        AGORA,
        "-o",
        tmp_path / "cli.json",
        "--rejects",
        tmp_path / "cli_r.csv",
        "--frame",
        "crop",
        "-q",
    )
    s = hpe.relabel_agora([AGORA], tmp_path / "api.json", fmt="coco", frame="crop", rejects=tmp_path / "api_r.csv")
    assert (tmp_path / "api.json").read_bytes() == (tmp_path / "cli.json").read_bytes()
    assert (tmp_path / "api_r.csv").read_bytes() == (tmp_path / "cli_r.csv").read_bytes()
    assert s.labelled + sum(s.reasons.values()) == s.people


def test_biwi(tmp_path):
    if not BIWI.is_dir():
        pytest.skip("no BIWI in ../shared/realdata")
    run("biwi", BIWI, "-o", tmp_path / "cli.parquet", "--camera", "rgb", "--split", "0.7,0.3", "-q")
    s = hpe.biwi_file(BIWI, tmp_path / "api.parquet", camera="rgb", split=(0.7, 0.3))
    assert (tmp_path / "api.parquet").read_bytes() == (tmp_path / "cli.parquet").read_bytes()
    assert s["splits"] and sum(s["splits"].values()) == s["sequences"]


def test_options_are_checked_once_with_the_commands_words():
    with pytest.raises(FormatSystemError, match="--format coco stores WHENet/DirectMHP angles"):
        RelabelPanopticOptions(fmt="coco", system="6drepnet")
    with pytest.raises(ValueError, match="expected A < B in --frames A:B, got '9:3'"):
        RelabelPanopticOptions(frames="9:3")
    assert RelabelPanopticOptions(frames="10:").frames == (10, None)
    assert RelabelPanopticOptions(fmt="whenet").system.name == "whenet"
    assert RelabelPanopticOptions().system.name == "300w_lp" and RelabelPanopticOptions().max_rmse == 2.0
    with pytest.raises(ValueError, match="expected every an integer >= 1, got 0"):
        RelabelPanopticOptions(every=0)
    with pytest.raises(FormatSystemError, match="--format whenet stores DirectMHP/WHENet angles"):
        RelabelAgoraOptions(fmt="whenet", system="biwi")
    assert RelabelAgoraOptions().max_rmse == 0.02
    with pytest.raises(ValueError, match="expected max_occlusion a number >= 0 or inf, got -1"):
        RelabelAgoraOptions(max_occlusion=-1)
    with pytest.raises(ValueError, match="expected camera depth or rgb, got 'ir'"):
        BiwiOptions(camera="ir")
    with pytest.raises(ValueError, match="expected protocol all or hopenet-99"):
        BiwiOptions(protocol="fsa")
    with pytest.raises(AttributeError):  # frozen
        BiwiOptions().seed = 1
