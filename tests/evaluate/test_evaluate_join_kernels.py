"""The key join's compiled kernels (``hpe_cli.native.hash_pairs``, ``first_unequal``) against plain Python: a dict of
the hashes, and string comparison of the paired keys. The numpy twins (``spill.hash_matches``, pyarrow's equal)
are compared with the same references in test_evaluate_join_hash_matches.py and test_evaluate_spill_join.py."""

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli import native
from hpe_cli.pipelines.evaluate.spill import hash_matches

needs_kernels = pytest.mark.skipif(native.kernels() is None, reason="_hpe_kernels not built")


def _oracle(hg, hp):
    if len(set(hg)) < len(hg) or len(set(hp)) < len(hp):
        return None
    where = {h: i for i, h in enumerate(hp)}
    gi = [i for i, h in enumerate(hg) if h in where]
    return gi, [where[hg[i]] for i in gi]


# values sharing their top bits land in one bucket; values sharing their low bits collide in the bucket's table
CLOSE = st.integers(0, 2**64 - 1).flatmap(
    lambda base: (
        st.integers(0, 255).map(lambda lo: (base & ~0xFF) | lo)
        | st.integers(0, 255).map(lambda hi: (base & ((1 << 56) - 1)) | (hi << 56))
    )
)
VALUES = st.lists(st.one_of(CLOSE, st.integers(0, 2**64 - 1), st.sampled_from([0, 1, 2**63, 2**64 - 1])), max_size=300)


@needs_kernels
@settings(max_examples=300, deadline=None)
@given(VALUES, VALUES, st.randoms(use_true_random=False), st.booleans())
def test_hash_pairs_equal_a_dict(g, p, rnd, dup):
    p = p + g[: len(g) // 2]  # some values on both sides
    if dup and p:
        p.append(p[0])  # a repeat on one side
    rnd.shuffle(p)
    want = _oracle(g, p)
    got = native.hash_pairs(np.array(g, dtype=np.uint64), np.array(p, dtype=np.uint64))
    if len(g) + len(p) < 64:
        assert got is None  # too few rows for the kernel: the caller sorts
        return
    if want is None:
        assert got is False
    else:
        assert got[0].tolist() == want[0] and got[1].tolist() == want[1]


@needs_kernels
def test_hash_pairs_many_rows_many_buckets():
    rng = np.random.default_rng(7)
    keys = rng.integers(0, 2**64 - 1, 400_000, dtype=np.uint64, endpoint=True)
    hg, hp = keys[:300_000], rng.permutation(keys[100_000:])
    gi, pi = native.hash_pairs(hg, hp)
    where = {int(h): i for i, h in enumerate(hp.tolist())}
    assert gi.tolist() == list(range(100_000, 300_000))
    assert pi.tolist() == [where[int(h)] for h in hg[100_000:300_000].tolist()]
    assert native.hash_pairs(hg, np.r_[hp, hp[-1:]]) is False
    assert native.hash_pairs(np.r_[hg[:5], hg], hp) is False


def test_hash_matches_same_pairs_with_and_without_kernels(monkeypatch):
    rng = np.random.default_rng(8)
    keys = rng.integers(0, 2**64 - 1, 5000, dtype=np.uint64, endpoint=True)
    hg, hp = keys[:4000], rng.permutation(keys[1000:])
    monkeypatch.setenv("HPE_KERNELS", "numpy")
    gi, pi = hash_matches(hg, hp)
    monkeypatch.delenv("HPE_KERNELS")
    gi2, pi2 = hash_matches(hg, hp)
    assert gi.tolist() == gi2.tolist() == list(range(1000, 4000)) and pi.tolist() == pi2.tolist()


TEXT = st.text(alphabet=st.sampled_from("ab/.é\\x"), max_size=6)


@needs_kernels
@settings(max_examples=300, deadline=None)
@given(st.lists(TEXT, min_size=1, max_size=30), st.lists(TEXT, min_size=1, max_size=30), st.data())
def test_first_unequal_equals_python(a, b, data):
    m = data.draw(st.integers(0, 40))
    ra = data.draw(st.lists(st.integers(0, len(a) - 1), min_size=m, max_size=m))
    rb = data.draw(st.lists(st.integers(0, len(b) - 1), min_size=m, max_size=m))
    types = (pa.string(), pa.large_string())
    ta, tb = data.draw(st.sampled_from(types)), data.draw(st.sampled_from(types))
    cut = data.draw(st.integers(0, 1))  # an array that is a slice of another (its own offset)
    arr_a = pa.array(["zz"] * cut + a, ta).slice(cut)
    arr_b = pa.array(b, tb)
    want = next((j for j in range(m) if a[ra[j]] != b[rb[j]]), -1)
    assert native.first_unequal(arr_a, np.array(ra, np.int64), arr_b, np.array(rb, np.int64)) == want
    if m <= len(a):  # rows_a None: a[j]
        want = next((j for j in range(m) if a[j] != b[rb[j]]), -1)
        assert native.first_unequal(arr_a.slice(0, m), None, arr_b, np.array(rb, np.int64)) == want


def test_first_unequal_leaves_nulls_and_other_types_to_pyarrow(monkeypatch):
    rows = np.array([0], np.int64)
    assert native.first_unequal(pa.array([None], pa.string()), None, pa.array(["a"]), rows) is None
    assert native.first_unequal(pa.array([1]), None, pa.array([1]), rows) is None
    monkeypatch.setenv("HPE_KERNELS", "numpy")
    assert native.first_unequal(pa.array(["a"]), None, pa.array(["a"]), rows) is None


@needs_kernels
def test_join_kernels_refuse_wrong_sizes_with_a_message():
    k = native.kernels()
    with pytest.raises(ValueError, match="expected 16 bytes"):
        k.hash_pairs(np.zeros(2, np.uint64), np.zeros(2, np.uint64), np.zeros(3, np.int64))
    off, data = np.array([0, 1], np.int32), b"a"
    with pytest.raises(ValueError, match="rows within"):
        k.first_unequal(off, data, None, off, data, np.array([1], np.int64), False, False)


@needs_kernels
@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 6), max_size=200), st.integers(7, 9), st.data())
def test_partition_rows_and_strings_are_a_stable_sort(parts, K, data):
    n = len(parts)
    part = np.array(parts, dtype=np.int16)
    rng = np.random.default_rng(n)
    cols = [rng.integers(0, 2**63, n, dtype=np.uint64), rng.random(n) < 0.5, rng.random((n, 3)), rng.random((n, 2, 5))]
    order = sorted(range(n), key=lambda i: parts[i])  # Python's sort is stable
    bounds, moved = native.partition_rows(part, K, cols)
    assert bounds.tolist() == [sum(p < k for p in parts) for k in range(K + 1)]
    for a, b in zip(cols, moved):
        assert b.shape == a.shape and b.dtype == a.dtype and b.tolist() == a[order].tolist()
    texts = data.draw(st.lists(TEXT, min_size=n + 1, max_size=n + 1))
    arr = pa.array(texts, data.draw(st.sampled_from([pa.string(), pa.large_string()]))).slice(1)
    got = native.partition_strings(part, K, arr)
    assert got.type == arr.type and got.to_pylist() == [texts[1 + i] for i in order]


@needs_kernels
def test_partition_kernels_refuse_bad_partitions():
    k = native.kernels()
    with pytest.raises(ValueError, match=r"partitions in \[0, K\)"):
        native.partition_rows(np.array([0, 3], np.int16), 3, [np.zeros(2)])
    with pytest.raises(ValueError, match=r"partitions in \[0, K\)"):
        native.partition_strings(np.array([0, -1], np.int16), 3, pa.array(["a", "b"]))
    with pytest.raises(ValueError, match="expected 16 bytes"):
        k.partition_scatter(np.zeros(2, np.int16), 2, np.zeros(3, np.int64), (np.zeros(2),), (np.zeros(1),), (8,))
