"""Exact percentiles from pieces (flat memory) equal np.percentile on the whole array, to the bit."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli.metrics.select import percentiles_of_pieces, top_counts

F32 = st.floats(width=32, allow_nan=False, allow_infinity=False, allow_subnormal=True)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(F32, min_size=1, max_size=300),
    st.lists(st.floats(0, 100), min_size=1, max_size=5),
    st.lists(st.integers(0, 300), max_size=4),
)
def test_percentiles_of_pieces_equal_numpy(values, q, cuts):
    v = np.array(values, dtype=np.float32)
    cuts = sorted(min(c, len(v)) for c in cuts)
    pieces = lambda: np.split(v, cuts)  # noqa: E731
    got = percentiles_of_pieces(pieces, len(v), q)
    want = np.percentile(v, q)
    assert got is not None
    np.testing.assert_array_equal(got, want)
    assert got.dtype == want.dtype


def test_report_percentiles_on_many_ties_and_large_sets():
    """Geodesic-like errors (ties, zeros, a heavy tail) in 64k pieces: np.percentile's numbers."""
    rng = np.random.default_rng(7)
    for v in (
        rng.exponential(4.0, 1_000_003),
        np.round(rng.uniform(0, 3, 500_000), 2),
        np.r_[np.zeros(70_000), rng.uniform(0, 180, 5)],
        np.full(100_000, 4.616041),
    ):
        v = v.astype(np.float32)
        pieces = lambda: (v[a : a + 65_536] for a in range(0, len(v), 65_536))  # noqa: E731
        q = [50, 90, 95]
        np.testing.assert_array_equal(percentiles_of_pieces(pieces, len(v), q), np.percentile(v, q))


def test_a_nan_or_a_wrong_count_is_not_answered():
    v = np.array([1.0, np.nan, 2.0], dtype=np.float32)
    assert percentiles_of_pieces(lambda: [v], 3, [50]) is None
    try:
        percentiles_of_pieces(lambda: [v[:1]], 3, [50])
    except ValueError as exc:
        assert "expected 3 values, got 1" in str(exc)
    else:
        raise AssertionError("a wrong count must raise")


@settings(max_examples=200, deadline=None)
@given(
    st.lists(F32, min_size=1, max_size=300),
    st.lists(st.floats(0, 100), min_size=1, max_size=5),
    st.lists(st.integers(0, 300), max_size=4),
    st.integers(1, 3),
)
def test_first_pass_counted_ahead_and_parts_on_threads_equal_numpy(values, q, cuts, threads):
    """The first pass summed piece by piece as the values are made (top_counts), the second over the values split
    in parts read on threads: np.percentile's numbers, to the bit."""
    v = np.array(values, dtype=np.float32)
    cuts = sorted(min(c, len(v)) for c in cuts)
    pieces = np.split(v, cuts)
    top = sum((top_counts(x) for x in pieces), np.zeros(1 << 16, dtype=np.int64))
    parts = [lambda x=x: [x[: len(x) // 2], x[len(x) // 2 :]] for x in pieces]
    got = percentiles_of_pieces(parts, len(v), q, top=top, threads=threads)
    want = np.percentile(v, q)
    np.testing.assert_array_equal(got, want)
    assert got.dtype == want.dtype


def test_top_counts_count_the_top_halves_of_the_bit_patterns():
    v = np.array([0.0, -0.0, 1.0, 1.0000001, -2.5, np.inf, 3.0e-45], dtype=np.float32)
    want = np.zeros(1 << 16, dtype=np.int64)
    for x in v:
        want[int(np.array([x], dtype=np.float32).view(np.uint32)[0]) >> 16] += 1
    np.testing.assert_array_equal(top_counts(v), want)


def test_an_infinite_value_is_left_to_numpy():
    """An infinity (or a NaN) seen in the first pass, counted ahead or not: None (the caller takes np.percentile)."""
    for bad in (np.inf, -np.inf, np.nan):
        v = np.array([1.0, bad, 2.0], dtype=np.float32)
        assert percentiles_of_pieces(lambda v=v: [v], 3, [50]) is None
        assert percentiles_of_pieces(lambda v=v: [v], 3, [50], top=top_counts(v)) is None
