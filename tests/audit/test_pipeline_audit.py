"""run_audit at scale-ish against independent oracles: pandas' duplicated() and the array checks."""

import re

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from hpe_cli.pipelines.audit import AuditOptions, run_audit
from hpe_cli.pipelines.audit.duplicates import string_hashes
from hpe_cli.rotation import get_system
from hpe_cli.rotation.audit import CHECKS, audit_angles


def test_string_hashes_equal_iff_equal():
    rng = np.random.default_rng(0)
    words = ["".join(rng.choice(list("abcé/._0123456789"), size=rng.integers(0, 30))) for _ in range(20000)]
    words = list(dict.fromkeys(words))
    arr = pa.array(words + words[:100] + [None, None])
    h = string_hashes(arr)
    assert len(np.unique(h[: len(words)])) == len(words)  # no collision among distinct strings
    assert np.array_equal(h[len(words) : len(words) + 100], h[:100])
    assert h[-1] == h[-2]
    # slices (non-zero offsets) and large_string give the same hashes
    assert np.array_equal(string_hashes(arr.slice(7, 50)), h[7:57])
    assert np.array_equal(string_hashes(arr.cast(pa.large_string())), h)


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_counts_and_duplicates_match_oracles(tmp_path, fmt):
    rng = np.random.default_rng(5)
    n = 6000
    pyr = np.c_[rng.uniform(-200, 200, n), rng.uniform(-95, 95, n), rng.uniform(-200, 200, n)].round(1)
    pyr[::97, 1] = 90.0
    pyr[::101] = np.nan
    pyr[::37] = pyr[0]
    df = pd.DataFrame(pyr, columns=["pitch", "yaw", "roll"])
    df["image"] = [f"im{i % 40}.jpg" if i % 37 == 0 else f"im{i}.jpg" for i in range(n)]
    path = tmp_path / f"a.{fmt}"
    df.to_parquet(path) if fmt == "parquet" else df.to_csv(path, index=False)
    system = get_system("300w_lp")
    rep = run_audit(path, system, AuditOptions(batch_size=1000))
    ref = audit_angles(pyr, system)
    for c in CHECKS[:-1]:
        assert rep[c] == int(ref[c].sum()), c
    key = df[["pitch", "yaw", "roll", "image"]].copy()
    dup = key.duplicated(keep="first").to_numpy()
    assert rep["duplicates"] == int(dup.sum())
    first_dups = np.flatnonzero(dup)[:5]
    got = rep["examples"]["duplicates"]
    base = 1 if fmt == "parquet" else 2  # Parquet: 1-based rows; CSV: file lines, header = line 1
    assert [e["row"] for e in got] == (first_dups + base).tolist()
    for e in got:
        i, j = e["row"] - base, e["same_as"] - base
        assert j < i and key.iloc[i].equals(key.iloc[j])
        assert not key.iloc[:j].isin(key.iloc[[i]].to_dict("list")).all(axis=1).any()
    flags = np.stack([ref[c] for c in CHECKS[:-1]] + [dup], axis=1)
    assert rep["details"]["flagged"] == int(flags.any(axis=1).sum())


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"near_tol_deg": -1}, "expected near_tol_deg in [0, 90], got -1"),
        ({"use": "quaternion"}, "expected use among auto, angles, matrix, got 'quaternion'"),
        ({"n_examples": -2}, "expected n_examples >= 0, got -2"),
        ({"threads": 0}, "expected threads >= 1, got 0"),
        ({"decoder": "nope"}, "expected decoder among synergynet, 3ddfa_v2, directmhp, got 'nope'"),
    ],
)
def test_audit_options_are_validated_once(kwargs, message):
    from hpe_cli.errors import HpeError

    with pytest.raises(HpeError, match=re.escape(message)):
        AuditOptions(**kwargs)


def test_audit_and_convert_options_normalise_and_validate():
    from hpe_cli.errors import HpeError
    from hpe_cli.pipelines.audit import ConsistencySettings
    from hpe_cli.pipelines.convert import ConvertOptions

    opts = AuditOptions(keys=["image", "id"], consistency=True)
    assert opts.keys == ("image", "id") and isinstance(opts.consistency, ConsistencySettings)
    with pytest.raises(HpeError, match=re.escape("convert options: expected batch_size >= 1, got 0")):
        ConvertOptions(batch_size=0)
    with pytest.raises(HpeError, match="expected decoder among"):
        ConvertOptions(decoder="x")
