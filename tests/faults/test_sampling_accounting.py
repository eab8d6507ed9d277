"""Every sampling rule of relabel-panoptic accounts for what it skips: labels + rejects = every view of the
frames in range, row for row (the oracle is the unsampled run: its labelled and rejected views together)."""

import pandas as pd
import pyarrow.parquet as pq
import pytest

from conftest import hpe

from .conftest import SYNTH

KEY = ["sequence", "frame", "person_id", "camera"]


def _relabel(tmp_path, name, *args):
    o, r = tmp_path / f"{name}.parquet", tmp_path / f"{name}.csv"
    res = hpe("relabel-panoptic", SYNTH, "-o", o, "--rejects", r, "--no-landmarks", *args)
    assert res.exit_code == 0, res.output
    t = pq.read_table(o).to_pandas()
    rj = pd.read_csv(r, dtype={"camera": str, "sequence": str})
    return t, rj, res.output


@pytest.fixture(scope="module")
def everything(tmp_path_factory):
    t, rj, _ = _relabel(tmp_path_factory.mktemp("all"), "all")
    views = pd.concat([t[KEY], rj[KEY]])
    assert not views.duplicated().any()
    return set(map(tuple, views.to_numpy().tolist()))


@pytest.mark.parametrize(
    "rule",
    [
        ["--every", "2"],
        ["--every", "3", "--workers", "2"],
        ["--every", "5", "--resume"],
        ["--min-change", "5"],
        ["--all-views"],
        ["--every", "2", "--min-change", "3", "--all-views"],
    ],
)
def test_labels_plus_rejects_are_every_view(tmp_path, everything, rule):
    t, rj, out = _relabel(tmp_path, "s", *rule)
    both = pd.concat([t[KEY], rj[KEY]])
    assert not both.duplicated().any()
    assert set(map(tuple, both.to_numpy().tolist())) == everything
    if "--every" in rule:
        n = int(rule[rule.index("--every") + 1])
        skipped = rj[rj["reason"] == "skipped by --every"]
        assert len(skipped) > 0 and ((skipped["frame"] - 100) % n != 0).all()
        assert ((t["frame"] - 100) % n == 0).all()
        assert skipped["detail"].str.contains(f"--every {n}").all()
        assert f"{len(skipped)} skipped by --every" in out
    labelled = int(out.split("labelled ")[1].split(" of ")[0])
    views = int(out.split("labelled ")[1].split(" of ")[1].split(" views")[0])
    assert labelled == len(t) and views == len(everything)


def test_strict_ignores_the_sampling_asked_for(tmp_path):
    o = tmp_path / "o.parquet"
    res = hpe(
        "relabel-panoptic", SYNTH, "-o", o, "--every", "2", "--strict", "--frames", "100:101", "--cameras", "00_00"
    )
    # frame 100 alone: whatever it rejects is a real failure, never the (absent) skipped frames
    assert "skipped by --every" not in res.output
