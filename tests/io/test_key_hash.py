"""Key hashes off the Arrow buffers: equal strings hash equal anywhere; the stem hash is the hash of the stem that
the join's regex gives (pyarrow's own ``replace_substring_regex`` as the oracle)."""

import pyarrow as pa
import pyarrow.compute as pc
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli.io.key_hash import string_hashes

TEXT = st.lists(st.sampled_from(list("ab./\\é0_") + [".jpg", "img", "/x/"]), max_size=8).map("".join)
STEM = r"^.*[\\/]|\.[^.\\/]*$"


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(TEXT, st.none()), min_size=1, max_size=40), st.integers(0, 5), st.booleans())
def test_equal_strings_equal_hashes_and_stems_as_the_regex(values, cut, large):
    arr = pa.array(values, pa.large_string() if large else pa.string())
    arr = arr.slice(min(cut, len(values) - 1))  # an offset into the buffers
    vals = arr.to_pylist()
    hx, hs = string_hashes(arr)
    stems = pc.replace_substring_regex(arr, STEM, "")
    shx, _ = string_hashes(pa.array(stems.to_pylist(), pa.string()))
    for i, v in enumerate(vals):
        if v is None:
            continue
        assert hs[i] == shx[i], (v, stems[i])  # the stem's hash is the hash of the stem
        for k, w in enumerate(vals):
            if w is not None and (v == w) != (hx[i] == hx[k]):
                raise AssertionError((v, w))
    # the same strings alone in their own array hash the same
    alone = string_hashes(pa.array([v for v in vals if v is not None], pa.string()))[0]
    assert list(alone) == [h for h, v in zip(hx, vals) if v is not None]
    nulls = [h for h, v in zip(hx, vals) if v is None]
    assert len(set(nulls)) <= 1


def test_spread_over_partitions():
    import numpy as np

    hx, hs = string_hashes(pa.array([f"img{i}" for i in range(200_000)]))
    assert len(np.unique(hx)) == 200_000 and (hx == hs).all()
    counts = np.bincount((hx % np.uint64(64)).astype(np.int64), minlength=64)
    assert counts.min() > 0.9 * 200_000 / 64


def test_powers_by_doubling_are_the_powers_mod_2_64():
    """The hash's power table (built by doubling, then grown) against Python's exact ``pow(base, k, 2**64)``."""
    import numpy as np

    from hpe_cli.io import key_hash as kh

    for base in (kh._P, kh._P_INV):
        kh._CACHE.pop(int(base), None)
        for n in (1, 5, 70_001, 200_003):  # the first call and each growth (doubling past the cache)
            got = kh._powers(base, n)
            assert got.dtype == np.uint64 and len(got) == n
            for k in sorted({0, 1, 2, n // 3, n // 2, n - 1} & set(range(n))):
                assert int(got[k]) == pow(int(base), k, 1 << 64), (n, k)


def _reference_hash(text: str) -> int:
    """The documented hash, one byte at a time in Python integers: ``sum b[i] P**i`` mod 2**64, the length times
    the golden ratio xored in, SplitMix64's finaliser."""
    m = 1 << 64
    h, p = 0, 1
    data = text.encode("utf-8")
    for b in data:
        h = (h + b * p) % m
        p = p * 0x100000001B3 % m
    h ^= len(data) * 0x9E3779B97F4A7C15 % m
    h ^= h >> 30
    h = h * 0xBF58476D1CE4E5B9 % m
    h ^= h >> 27
    h = h * 0x94D049BB133111EB % m
    return h ^ (h >> 31)


@settings(max_examples=200, deadline=None)
@given(st.lists(TEXT, min_size=1, max_size=30), st.integers(0, 5))
def test_hash_values_are_the_documented_polynomial(values, cut):
    """The values themselves are pinned (not only their equalities): the key join partitions rows by them, and the
    order of evaluate's per-row output follows the partitions."""
    arr = pa.array(values, pa.string()).slice(min(cut, len(values) - 1))
    hx, hs = string_hashes(arr)
    stems = pc.replace_substring_regex(arr, STEM, "").to_pylist()
    assert [int(h) for h in hx] == [_reference_hash(v) for v in arr.to_pylist()]
    assert [int(h) for h in hs] == [_reference_hash(v) for v in stems]
