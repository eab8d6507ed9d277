"""EvaluateOptions (one frozen settings object, validated once) and each side opened once per run.

The Python API (:func:`hpe_cli.api.evaluate_files`) and ``hpe evaluate`` build the same options and give the same
report; a run resolves each side's rotation system once, whatever the passes (files in different orders spilled
and joined by key, opal23-align's second pass).
"""

import dataclasses
import json
from pathlib import Path

import pandas as pd
import pytest

import hpe_cli
from conftest import hpe
from hpe_cli.errors import HpeError
from hpe_cli.pipelines.evaluate import EvaluateOptions, run_evaluate

GOLD = Path(__file__).resolve().parents[3] / "shared" / "golden" / "evaluate"
needs_gold = pytest.mark.skipif(not GOLD.is_dir(), reason="shared/golden/evaluate not available")


@pytest.mark.parametrize(
    ("field", "value", "expected"),
    [
        ("align", "median", "expected align among none, mean, got 'median'"),
        ("join_mode", "rows", "expected join_mode among key, order, got 'rows'"),
        ("join_engine", "duck", "expected join_engine among spill, memory, got 'duck'"),
        ("batch_size", 0, "expected batch_size >= 1, got 0"),
        ("threads", 0, "expected threads >= 1, got 0"),
        ("worst", -1, "expected worst >= 0, got -1"),
        ("yaw_bins", 0.0, "expected yaw_bins > 0 (degrees), got 0.0"),
    ],
)
def test_options_are_validated_once(field, value, expected):
    with pytest.raises(HpeError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        EvaluateOptions(**{field: value})


def test_options_are_frozen_and_normalised():
    o = EvaluateOptions(keys=["image"], protocols=["hopenet"])
    assert o.keys == ("image",) and o.protocols == ("hopenet",)
    assert len(EvaluateOptions().protocols) > 1  # None: every protocol
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.align = "mean"
    with pytest.raises(HpeError, match="nosuch"):
        EvaluateOptions(protocols=["nosuch"])


@needs_gold
def test_api_and_cli_give_the_same_report(tmp_path):
    pred = tmp_path / "pred.csv"
    pd.read_csv(GOLD / "syn" / "pred.csv").sample(frac=1.0, random_state=2).to_csv(pred, index=False)
    gt = GOLD / "syn" / "gt.csv"
    report = tmp_path / "cli.json"
    args = ["evaluate", str(pred), str(gt), "--pred-system", "300w_lp", "--gt-system", "300w_lp"]
    hpe(*args, "--protocol", "hopenet", "--json", report, "-q", ok=True)
    api = hpe_cli.evaluate_files(pred, gt, pred_system="300w_lp", gt_system="300w_lp", protocols=["hopenet"])
    same = hpe_cli.evaluate_files(
        pred, gt, EvaluateOptions(pred_system="300w_lp", gt_system="300w_lp", protocols=("hopenet",))
    )
    assert json.loads(report.read_text()) == json.loads(json.dumps(api)) == json.loads(json.dumps(same))
    with pytest.raises(TypeError, match="expected options or settings"):
        hpe_cli.evaluate_files(pred, gt, EvaluateOptions(), threads=1)


@needs_gold
@pytest.mark.parametrize("shuffled", [False, True])
def test_each_side_is_opened_and_resolved_once(tmp_path, monkeypatch, shuffled):
    import hpe_cli.io.readers as readers
    import hpe_cli.io.system_meta as system_meta
    import hpe_cli.pipelines.evaluate.run as er
    import hpe_cli.pipelines.evaluate.sides as es

    calls = []
    resolve, open_table = system_meta.resolve_system, readers.open_table
    for mod in (es, system_meta):  # the name evaluate calls, and the owner's (no other path resolves again)
        monkeypatch.setattr(mod, "resolve_system", lambda *a, **k: calls.append("resolve") or resolve(*a, **k))
    for mod in (er, readers):
        monkeypatch.setattr(mod, "open_table", lambda *a, **k: calls.append("open") or open_table(*a, **k))
    pred = tmp_path / "pred.csv"
    p = pd.read_csv(GOLD / "syn" / "pred.csv")
    (p.sample(frac=1.0, random_state=4) if shuffled else p).to_csv(pred, index=False)
    options = EvaluateOptions(
        pred_system="300w_lp", gt_system="300w_lp", protocols=("opal23-align", "hopenet"), align="mean", batch_size=97
    )
    rep = run_evaluate(pred, GOLD / "syn" / "gt.csv", options)
    assert rep["n"]["pairs"] == len(p)
    assert ("partition(s) on disk" in rep["inputs"]["paired"]) == shuffled
    assert sorted(calls) == ["open", "open", "resolve", "resolve"]


def test_api_batch_size_default_is_the_commands():
    """EvaluateOptions() reads batches of the size ``hpe evaluate`` reads (a 4x larger default doubled the API's
    peak memory at 5M pairs, 930 against 450 MB, for no speed)."""
    from hpe_cli.cli.evaluate import evaluate as command
    from hpe_cli.pipelines.evaluate.options import EvaluateOptions

    default = next(p.default for p in command.params if p.name == "batch_size")
    assert EvaluateOptions().batch_size == default
