"""The streamed run's duplicate-key check (KeysSeen) against Python's own set of the keys: a repeat anywhere in
the file, and only then, sends the run to the key join; whichever chunks come with their hashes sorted on the
label threads, and on 1 or 2 threads."""

from types import SimpleNamespace

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli.pipelines.evaluate.lockstep import KeysSeen, Unaligned
from hpe_cli.pipelines.evaluate.sides import Chunk


def _chunks(table, sizes, reader, prepared):
    """The table in chunks of ``sizes`` as a reader hands them over: prepared on its label threads while asked
    (``prepared[k]`` False: this one not, as if it had been labelled before)."""
    a = 0
    for k, n in enumerate(sizes):
        t = table.slice(a, n)
        a += n
        c = Chunk(None, np.ones(n, dtype=bool), None, None, None, t, None, np.arange(n) + a + 2)
        if reader.prepare is not None and prepared[k % len(prepared)]:
            c.prepared = reader.prepare(c)
        yield c


def _verdict(table, keys, sizes, threads, prepared) -> bool:
    reader = SimpleNamespace(prepare=None)
    seen = KeysSeen(keys, reader, threads)
    try:
        for c in _chunks(table, sizes, reader, prepared):
            seen.add(c)
        seen.check()
    except Unaligned:
        return True
    finally:
        seen.close()
    return False


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.text("ab/.", max_size=4), min_size=1, max_size=120),
    st.lists(st.integers(1, 40), min_size=1, max_size=8),
    st.sampled_from([1, 2]),
    st.lists(st.booleans(), min_size=1, max_size=4),
)
def test_a_repeated_key_anywhere_and_only_then(names, sizes, threads, prepared):
    names = ["z9", "z8"] + names  # a first chunk out of order: every key is hashed (not in the alphabet: unique)
    sizes = [2 + sizes[0]] + sizes[1:]
    sizes = (sizes * (len(names) // sum(sizes) + 1))[: len(names)]
    cut = np.cumsum(sizes)
    sizes = np.diff(np.r_[0, cut[cut < len(names)], len(names)]).tolist()
    table = pa.table({"image": pa.array(names, pa.string())})
    assert _verdict(table, ["image"], sizes, threads, prepared) == (len(set(names)) < len(names))


@pytest.mark.parametrize("threads", [1, 2])
def test_many_keys_in_many_chunks(threads):
    """50,000 keys in 64-row chunks (every partition file used), two key columns: a repeat 40,000 rows apart is
    found, a file without one passes; keys in increasing order are not hashed."""
    rng = np.random.default_rng(4)
    ids = rng.permutation(50_000)
    cols = {"image": pa.array([f"img{i}" for i in ids]), "cam": pa.array((ids % 7).astype(np.int64))}
    sizes = [64] * (50_000 // 64) + [50_000 % 64]
    assert not _verdict(pa.table(cols), ["image", "cam"], sizes, threads, [True, False, True])
    twice = ids.copy()
    twice[45_000] = twice[5_000]
    cols = {"image": pa.array([f"img{i}" for i in twice]), "cam": pa.array((twice % 7).astype(np.int64))}
    assert _verdict(pa.table(cols), ["image", "cam"], sizes, threads, [True, False, True])
    ordered = pa.table({"image": pa.array([f"img{i:06d}" for i in range(50_000)])})
    reader = SimpleNamespace(prepare=None)
    seen = KeysSeen(["image"], reader, threads)
    hashed = 0
    for c in _chunks(ordered, sizes, reader, [True]):
        hashed += c.prepared is not None
        seen.add(c)
    seen.check()  # the reader hashed the first chunk only (asked up front, told to stop once its keys increase)
    assert seen.files is None and reader.prepare is None and hashed == 1
