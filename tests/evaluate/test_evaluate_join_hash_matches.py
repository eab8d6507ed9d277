"""The key join's hash pairing (``spill.hash_matches``: one SIMD sort of both sides' hashes with the side and row
packed below their top bits) against a Python dict, and the streamed attempt's early exit on Parquet files in
different orders (``lockstep.first_keys_differ``) against the run without it: the same report and bytes."""

import json

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli.pipelines.evaluate import EvaluateOptions, run_evaluate
from hpe_cli.pipelines.evaluate import lockstep as ls
from hpe_cli.pipelines.evaluate.spill import hash_matches
from hpe_cli.rotation.systems import get_system


def _oracle(hg, hp):
    if len(set(hg.tolist())) < len(hg) or len(set(hp.tolist())) < len(hp):
        return None
    where = {h: i for i, h in enumerate(hp.tolist())}
    gi = [i for i, h in enumerate(hg.tolist()) if h in where]
    return gi, [where[hg[i]] for i in gi]


# hashes that share their top bits (the packed sort sees them as equal until the whole hashes are compared)
NEAR = st.integers(0, 2**64 - 1).flatmap(lambda base: st.integers(0, 4095).map(lambda lo: (base & ~0xFFF) | lo))
HASHES = st.lists(st.one_of(NEAR, st.integers(0, 2**64 - 1), st.sampled_from([0, 1, 2**63, 2**64 - 1])), max_size=40)


@settings(max_examples=400, deadline=None)
@given(HASHES, HASHES, st.randoms(use_true_random=False))
def test_hash_matches_equal_a_dict(g, p, rnd):
    shared = g[: len(g) // 2]
    p = p + shared  # some keys on both sides
    rnd.shuffle(p)
    hg, hp = np.array(g, dtype=np.uint64), np.array(p, dtype=np.uint64)
    want, got = _oracle(hg, hp), hash_matches(hg, hp)
    if want is None:
        assert got is None
    else:
        assert got is not None
        assert got[0].tolist() == want[0] and got[1].tolist() == want[1]


def test_hash_matches_many_rows():
    rng = np.random.default_rng(3)
    keys = rng.integers(0, 2**64 - 1, 300_000, dtype=np.uint64, endpoint=True)
    hg, hp = keys[:250_000], rng.permutation(keys[50_000:])
    gi, pi = hash_matches(hg, hp)
    assert (gi == np.arange(50_000, 250_000)).all() and (hp[pi] == hg[gi]).all()
    assert hash_matches(hg, np.r_[hp, hp[:1]]) is None  # a duplicate on one side


@pytest.fixture
def parquet_pair(tmp_path):
    rng = np.random.default_rng(0)
    n = 3000
    gt = pd.DataFrame(
        {
            "image": [f"img{i}.jpg" for i in range(n)],
            "pitch": rng.uniform(-80, 80, n),
            "yaw": rng.uniform(-89, 89, n),
            "roll": rng.uniform(-80, 80, n),
        }
    )
    pred = gt.copy()
    pred[["pitch", "yaw", "roll"]] += rng.normal(0, 3, (n, 3))
    gt.to_parquet(tmp_path / "gt.parquet")
    pred.to_parquet(tmp_path / "ordered.parquet")
    pred.sample(frac=1.0, random_state=1).to_parquet(tmp_path / "shuffled.parquet")
    return tmp_path


@pytest.mark.parametrize("order", ["ordered", "shuffled"])
def test_first_keys_check_changes_nothing(parquet_pair, monkeypatch, order):
    s = get_system("300w_lp")
    seen = []
    real = ls.first_keys_differ

    def counted(gr, pr, keys):
        seen.append(real(gr, pr, keys))
        return seen[-1]

    def run(name):
        out = parquet_pair / f"{name}.rows.parquet"
        rep = run_evaluate(
            parquet_pair / f"{order}.parquet",
            parquet_pair / "gt.parquet",
            EvaluateOptions(pred_system=s, gt_system=s, output=out, batch_size=700, overwrite=True),
        )
        return json.dumps(rep, sort_keys=True), out.read_bytes()

    monkeypatch.setattr(ls, "first_keys_differ", counted)
    with_check = run("with")
    assert seen and seen[0] is (order == "shuffled")
    monkeypatch.setattr(ls, "first_keys_differ", lambda gr, pr, keys: False)
    assert run("without") == with_check
