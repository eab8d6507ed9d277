"""Streaming ``hpe evaluate``'s two inputs side by side when they list the same keys in the same order.

:func:`lockstep` pairs equal-length chunks of the two sides as they are read, checks the keys chunk by chunk
(:func:`_same_keys`) and duplicate keys across chunks (:class:`KeysSeen`); :class:`Unaligned` sends the run to
the key join (:mod:`hpe_cli.pipelines.evaluate.spill`). :func:`prefetch` reads one pair ahead on a thread.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import numpy as np
import pyarrow as pa

from ...io.key_hash import string_hashes
from .join import JoinUsageError
from .sides import Chunk, SideReader, file_stems, keys_hash


class Unaligned(Exception):
    """The two files do not list the same keys in the same order: pair them with the in-memory join."""


def _same_keys(g: Chunk, p: Chunk, keys, notes: set) -> None:

    for k in keys:
        a, b = g.keys.column(k), p.keys.column(k)
        if a.type == b.type and a.null_count == 0 and b.null_count == 0 and a.equals(b):
            continue  # the same values (one comparison of the buffers, about 5x cheaper than equal + all)
        import pyarrow.compute as pc  # lazy: start-up (0.06 s; keys written alike need none)

        a, b = (x.cast(x.type.value_type) if pa.types.is_dictionary(x.type) else x for x in (a, b))
        if a.type != b.type:
            a, b = pc.cast(a, pa.string()), pc.cast(b, pa.string())
        if pc.all(pc.equal(a, b)).as_py() is not False and a.null_count == 0 and b.null_count == 0:
            continue
        if pa.types.is_string(a.type) and pc.all(pc.equal(file_stems(a), file_stems(b))).as_py():
            notes.add(f"key {k!r} joined on file stems (the two files spell the names differently)")
            continue
        raise Unaligned(k)


class KeysSeen:
    """Duplicate keys across the chunks of a streamed pair of files (the key join names them).

    Keys that increase strictly through the whole file cannot repeat: only the last key of each chunk is kept.
    Otherwise, from the first chunk on, each row's 64-bit key hash is spilled into one of 16 files by its top
    bits, and :meth:`check` sorts each file (``threads`` at a time; memory flat in the rows). A file whose keys
    increase for a while and then do not goes to the key join (its first rows were not hashed).

    Each GT chunk is added whole, as read (a run that ends has paired every GT row). Its hashes are computed and
    sorted (:meth:`prepare`) on the reader's label threads, beside the labels, so the thread that pairs the
    chunks only writes 16 slices of a sorted array (one :func:`numpy.searchsorted`); the files then hold sorted
    runs. The reader is asked for them from the first chunk on, and told to stop when that chunk's keys
    increase (the few chunks labelled ahead by then are hashed for nothing).
    """

    def __init__(self, keys, reader=None, threads: int = 1):
        self.keys, self.last, self.sorted, self.files, self.folder = list(keys), None, True, None, None
        self.reader = reader  # asked to hash (and sort) the keys of the chunks it labels
        self.threads = max(1, int(threads))
        self.asked = reader is not None and reader.prepare is None
        if self.asked:  # from the first chunk on (the few labelled ahead of the pairing too)
            reader.prepare = self.prepare

    def add(self, g: Chunk) -> None:

        if not g.n:
            return
        if self.sorted and len(self.keys) == 1:
            col = g.keys.column(self.keys[0])
            col = col.combine_chunks() if isinstance(col, pa.ChunkedArray) else col
            ok = col.null_count == 0 and (g.n < 2 or _increasing(col))
            if ok and self.last is not None:
                import pyarrow.compute as pc  # lazy: start-up (0.06 s; only files whose keys increase get here)

                ok = pc.greater(col[0], self.last).as_py()
            if ok:
                if self.asked:  # increasing keys: the chunks labelled from now on are not hashed
                    self.reader.prepare = None
                    self.asked = False
                self.last = col[g.n - 1]
                return
            if self.last is not None:  # sorted so far, not from here on: the earlier rows were not hashed
                raise Unaligned("keys not in order after a sorted start")
        self.sorted = False
        self._spill(g)

    def prepare(self, c: Chunk):
        """The reader's ``prepare`` (on its label threads): the chunk's key hashes, sorted."""
        return None if c.keys is None else SortedHashes(sorted_hashes(c.keys, self.keys))

    def _spill(self, g: Chunk) -> None:

        h = g.prepared.hashes if isinstance(g.prepared, SortedHashes) else None
        if h is None:  # a reader not asked (its chunks came before, or it prepares something else): here
            h = sorted_hashes(g.keys, self.keys)
        if self.files is None:
            self.folder = tempfile.mkdtemp(prefix="hpe_eval_keys_")
            self.files = [  # a chunk writes about 32 kB to each: buffered, one write for about two chunks
                open(os.path.join(self.folder, f"{b:02d}.bin"), "wb", buffering=WRITE_BUFFER)  # noqa: SIM115
                for b in range(16)
            ]
        bounds = np.searchsorted(h, PART_STARTS).tolist() + [len(h)]  # partition b: top 4 bits equal to b
        for b in range(16):
            if bounds[b + 1] > bounds[b]:
                self.files[b].write(h[bounds[b] : bounds[b + 1]])

    def check(self) -> None:
        """Raise :class:`Unaligned` when a key hash repeats (a duplicate key, or a collision the join settles)."""
        if self.files is None:
            return
        try:
            for f in self.files:
                f.close()
            names = [f.name for f in self.files]
            if self.threads > 1:  # np.sort and the reads release the GIL; any repeat, whichever file: one verdict
                with ThreadPoolExecutor(self.threads, thread_name_prefix="hpe-evaluate-keys") as ex:
                    repeats = list(ex.map(_repeats, names))
            else:
                repeats = [_repeats(name) for name in names]
            if any(repeats):
                raise Unaligned("duplicate")
        finally:
            self.close()

    def close(self) -> None:

        for f in self.files or ():
            f.close()
        if self.folder:
            shutil.rmtree(self.folder, ignore_errors=True)
        self.files = self.folder = None


def _increasing(col) -> bool:
    """Whether the values of an Arrow array (no nulls) increase strictly. Its first 257 values are compared in
    Python first (the same order as Arrow's: code points of strings are their UTF-8 bytes' order), where most
    files whose keys do not increase show it, without importing ``pyarrow.compute``."""
    head = col.slice(0, 257).to_pylist()
    if not all(a < b for a, b in zip(head, head[1:])):
        return False
    import pyarrow.compute as pc  # lazy: start-up (0.06 s; only files whose first keys increase get here)

    return pc.all(pc.greater(col.slice(1), col.slice(0, len(col) - 1))).as_py()


#: bytes each of :class:`KeysSeen`'s 16 files gathers before a write (16 of them: 1 MB at most)
WRITE_BUFFER = 1 << 16
#: the first hash of each of :class:`KeysSeen`'s 16 partitions (its top 4 bits)
PART_STARTS = np.arange(16, dtype=np.uint64) << np.uint64(60)


class SortedHashes:
    """A chunk's key hashes (uint64), sorted: what :meth:`KeysSeen.prepare` makes of it on a label thread."""

    __slots__ = ("hashes",)

    def __init__(self, hashes: np.ndarray):
        self.hashes = hashes


def sorted_hashes(table, keys) -> np.ndarray:
    """The 64-bit hashes of the ``keys`` columns of ``table`` (:func:`~.sides.keys_hash`), sorted (in place)."""
    h = keys_hash(table, keys)
    h.sort()
    return h


def _repeats(name: str) -> bool:
    """Whether a file of uint64 hashes holds one twice."""
    h = np.fromfile(name, dtype=np.uint64)
    h.sort()
    return bool(len(h) > 1 and (h[1:] == h[:-1]).any())


def _stems_differ(a, b, keys) -> bool:
    """Whether the file stems of a text key column of two record batches differ in a row, told by their hashes
    (:func:`hpe_cli.io.key_hash.string_hashes`: equal texts have equal hashes, so unequal hashes prove unequal
    stems, and the texts differ too): then :func:`_same_keys` would say :class:`Unaligned`, here without
    ``pyarrow.compute`` (0.06 s to import) or a regular expression. False when it cannot tell."""
    for k in keys:
        x, y = a.column(k), b.column(k)
        if x.type == y.type and pa.types.is_string(x.type) and not x.null_count and not y.null_count:
            if (string_hashes(x)[1] != string_hashes(y)[1]).any():
                return True
    return False


def first_keys_differ(gr: SideReader, pr: SideReader, keys) -> bool:
    """Whether the first batches of two Parquet files already pair different keys, the check :func:`lockstep`
    makes on its first pair of chunks, on the key columns alone: files in different orders go to the key join
    without labelling (and throwing away) their first batches. False when it cannot tell cheaply (not Parquet,
    an empty first batch, a ``.mat`` folder's stems)."""

    if not keys or gr.dataset_stem or pr.dataset_stem or not (gr.src.kind == pr.src.kind == "parquet"):
        return False
    firsts = []
    for r in (gr, pr):
        batches = r.src.batches_with_rejects()
        try:
            batch, _ = next(batches, (None, None))
        finally:
            batches.close()
        if batch is None or batch.num_rows == 0 or any(k not in batch.schema.names for k in keys):
            return False
        firsts.append(batch.select(keys))
    m = min(t.num_rows for t in firsts)
    if _stems_differ(firsts[0].slice(0, m), firsts[1].slice(0, m), keys):
        return True
    g, p = (SimpleNamespace(keys=t.slice(0, m)) for t in firsts)
    try:
        _same_keys(g, p, keys, set())
    except Unaligned:
        return True
    return False


def lockstep(gr: SideReader, pr: SideReader, keys, join_mode: str, notes: set):
    """Pairs of equal-length chunks of the two sides, in file order; keys verified chunk by chunk.

    Raises :class:`Unaligned` (key join) when the keys differ or one side has
    rows left over, :class:`JoinUsageError` (``--join order``) on unequal counts.
    """
    if join_mode != "order" and first_keys_differ(gr, pr, keys):
        raise Unaligned("first keys")
    gi, pi = gr.chunks(), pr.chunks()
    seen = KeysSeen(keys, gr, gr.threads) if keys else None
    try:
        yield from _lockstep(gr, pr, gi, pi, keys, join_mode, notes, seen)
        if seen is not None:
            seen.check()
    finally:  # an abandoned side (Unaligned, an error) stops its label threads now, not at exit
        gi.close()
        pi.close()
        if seen is not None:
            seen.close()


def _lockstep(gr, pr, gi, pi, keys, join_mode, notes, seen):
    gbuf = pbuf = None
    while True:
        while gbuf is None or gbuf.n == 0:
            gbuf = next(gi, None)
            if gbuf is None:
                break
            if seen is not None:  # each GT chunk whole, as read (a run ends with every GT row paired, or stops)
                seen.add(gbuf)
        while pbuf is None or pbuf.n == 0:
            pbuf = next(pi, None)
            if pbuf is None:
                break
        if gbuf is None or pbuf is None:
            break
        m = min(gbuf.n, pbuf.n)
        g, p = gbuf.slice(0, m), pbuf.slice(0, m)
        gbuf, pbuf = gbuf.slice(m, gbuf.n), pbuf.slice(m, pbuf.n)
        if keys:
            _same_keys(g, p, keys, notes)
        yield g, p
    if (
        (gbuf is not None and gbuf.n)
        or (pbuf is not None and pbuf.n)
        or next(gi, None) is not None
        or next(pi, None) is not None
    ):
        if join_mode == "order":
            for _ in gi:
                pass
            for _ in pi:
                pass
            raise JoinUsageError(
                f"{pr.path}: --join order pairs rows by position and needs equal row counts; "
                f"got {pr.n} predictions and {gr.n} ground-truth rows in {gr.path}"
            )
        raise Unaligned("row counts")


_END = object()


def prefetch(gen):
    """Iterate ``gen`` one item ahead in one worker thread (Parquet/CSV decoding and numpy release the GIL).

    The worker only ever runs one ``next(gen)`` at a time and is joined before
    this generator returns or raises, so no thread outlives the run.
    """

    ex = ThreadPoolExecutor(1, thread_name_prefix="hpe-evaluate-read")
    try:
        fut = ex.submit(next, gen, _END)
        while True:
            item = fut.result()
            if item is _END:
                return
            fut = ex.submit(next, gen, _END)
            yield item
    finally:
        ex.shutdown(wait=True, cancel_futures=True)
        if hasattr(gen, "close"):  # after the worker is joined: the generator is not running
            gen.close()
