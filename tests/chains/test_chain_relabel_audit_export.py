"""relabel-panoptic -> audit --consistency --suspects -> export/convert --exclude: the suspects leave the data set.

The relabelled CMU Panoptic pizza1 sample has suspects (its landmarks disagree with
the label of some faces, e.g. frame 6328 person 1 in every camera); the key list
``audit --suspects`` writes is read back by ``export --exclude`` and
``convert --exclude``: each suspect row is in their rejects with ``excluded:
<reason>`` and in none of their outputs; every other row is where it was.
"""

from __future__ import annotations

import pandas as pd
import pytest

from conftest import hpe

from .conftest import PIZZA

KEYS = ["sequence", "frame", "camera", "person_id"]


@pytest.fixture(scope="module")
def audited(tmp_path_factory):
    if not PIZZA.exists():
        pytest.skip("realdata pizza1 sample not available")
    tmp = tmp_path_factory.mktemp("chain")
    lab = tmp / "labels.parquet"
    hpe("relabel-panoptic", PIZZA, "-o", lab, "-q", "--rejects", tmp / "relabel_rejects.csv", ok=True)
    sus = tmp / "suspects.csv"
    hpe("audit", lab, "--consistency", "--suspects", sus, "-o", tmp / "scored.parquet", "-q", ok=True)
    return tmp, lab, sus


def _keyset(frame):
    return set(map(tuple, frame[KEYS].astype(str).to_numpy().tolist()))


def test_suspects_list_is_a_key_list_with_reasons(audited):
    tmp, lab, sus = audited
    s = pd.read_csv(sus)
    assert {"image", *KEYS, "row", "score", "reason"} <= set(s.columns)
    assert len(s) > 0 and (s["reason"] != "").all()
    scored = pd.read_parquet(tmp / "scored.parquet")
    assert _keyset(s) == _keyset(scored[scored["suspect"]])


def test_convert_exclude_drops_exactly_the_suspects(audited):
    tmp, lab, sus = audited
    out, rej = tmp / "kept.parquet", tmp / "convert_rejects.csv"
    res = hpe("convert", lab, "-o", out, "--to", "6drepnet", "--exclude", sus, "--rejects", rej, ok=True)
    s, kept, all_rows = pd.read_csv(sus), pd.read_parquet(out), pd.read_parquet(lab)
    assert f"excluded: {len(s)} rows" in res.output
    assert _keyset(kept) == _keyset(all_rows) - _keyset(s)
    r = pd.read_csv(rej)
    assert _keyset(r) == _keyset(s)
    assert r["reason"].str.startswith("excluded: ").all()


def test_convert_exclude_without_rejects_file_is_not_an_error(audited):
    tmp, lab, sus = audited
    out = tmp / "kept2.parquet"
    hpe("convert", lab, "-o", out, "--to", "300w_lp", "--exclude", sus, ok=True)
    assert len(pd.read_parquet(out)) == len(pd.read_parquet(lab)) - len(pd.read_csv(sus))


def test_export_exclude_lists_the_suspects_as_excluded(audited):
    tmp, lab, sus = audited
    rej = tmp / "export_rejects.csv"
    hpe(
        "export",
        lab,
        "-o",
        tmp / "hf",
        "--layout",
        "hf",
        "--images",
        PIZZA,
        "--exclude",
        sus,
        "--rejects",
        rej,
        "-q",
        ok=True,
    )
    s, r = pd.read_csv(sus), pd.read_csv(rej)
    ex = r[r["reason"].str.startswith("excluded: ")]
    assert _keyset(ex) == _keyset(s)
    # an excluded row keeps its audit reason
    assert ex["reason"].str.contains("deg").all()


def test_exclude_file_without_keys_is_one_line_error(audited, tmp_path):
    tmp, lab, sus = audited
    bad = tmp_path / "bad.csv"
    bad.write_text("reason\nx\n")
    res = hpe("convert", lab, "-o", tmp_path / "o.parquet", "--to", "300w_lp", "--exclude", bad)  # fmt: skip
    assert res.exit_code == 1
    assert f"{bad}: expected key columns" in res.output and "Traceback" not in res.output
