"""External hash join of ``hpe evaluate``'s two inputs when they do not list the keys in the same order.

Both sides are streamed once (:class:`~hpe_cli.pipelines.evaluate.sides.SideReader`) and every row is written
to one of ``K`` partition files (Arrow IPC, in a temporary folder) chosen by a hash of its key, so rows with
equal keys (also equal file stems, see :func:`~hpe_cli.pipelines.evaluate.join._key_codes`) land in the same
partition. ``K`` is chosen from the row count so that one partition of both sides is about
:data:`PARTITION_ROWS` rows (~100 MB on disk). The partitions are then joined one at a time with the in-memory
join (:func:`~hpe_cli.pipelines.evaluate.join.join`), so memory is flat in the number of pairs, and a key that
appears twice anywhere in a file is found in its partition. Whether text keys are compared as written or on
their file stems is decided over the whole files first, as the in-memory join decides it.

Where the compiled kernels are built (:mod:`hpe_cli.native`), a chunk's rows are put in partition order by one
counting sort (``partition_rows``, ``partition_strings``), a partition's rows are paired by their key hashes in
cache-sized buckets (``hash_pairs``) and every pair is verified on the key bytes (``first_unequal``); their numpy
and pyarrow twins give the same rows and pairs.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing

import numpy as np
import pyarrow as pa

from ...io.key_hash import string_hashes
from ...io.layout import arrow_to_numpy, numpy_to_arrow
from ...native import first_unequal, hash_pairs, partition_rows, partition_strings
from .join import Matched
from .sides import Side, combine_key_hash, file_stems, key_text


def _bools(col) -> np.ndarray:
    """A boolean Arrow column (no nulls) as a numpy bool array, from its bit buffers (no pandas)."""

    chunks = col.chunks if isinstance(col, pa.ChunkedArray) else [col]
    parts = [
        np.unpackbits(np.frombuffer(ch.buffers()[1], dtype=np.uint8), bitorder="little")[
            ch.offset : ch.offset + len(ch)
        ].astype(bool)
        for ch in chunks
        if len(ch)
    ]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=bool)


#: rows of one side per partition (about 130 bytes each on disk, ~550 bytes each while a partition is joined)
PARTITION_ROWS = 400_000
#: rows of one side labelled and written at once while the partition files are filled
GROUP_ROWS = 1 << 17
#: at most this many partition files per side open at once
MAX_PARTITIONS = 400
_PFX = "__hpe_"


def key_hashes(keys_table, keys):
    """``(partition hash, {key: (hash of the text, hash of its file stem)})`` of each row, uint64.

    The partition hash combines the stem hashes of all key columns, so equal keys and equal stems land in
    the same partition; the per-column hashes let :meth:`Partitions.stem_columns` count matches cheaply.
    Hashed off the Arrow buffers (:func:`hpe_cli.io.key_hash.string_hashes`).
    """

    h = np.zeros(keys_table.num_rows, dtype=np.uint64)
    per = {}
    for k in keys:
        hx, hs = string_hashes(key_text(keys_table.column(k)))
        per[k] = (hx, hs)
        h = combine_key_hash(h, hs)
    return h, per


def _one_array(col):
    """A column as one Arrow array (its one chunk as it is: ``combine_chunks`` would copy it)."""
    if isinstance(col, pa.ChunkedArray):
        return col.chunk(0) if col.num_chunks == 1 else col.combine_chunks()
    return col


def stem_hashes(col) -> np.ndarray:
    """The hashes of the file stems of a key column (:func:`key_hashes`' second hash), computed again from the key
    where a side's stems differ from its texts (the partition files keep the hashes of the texts only)."""
    return string_hashes(key_text(col))[1]


def _count_in(a, b) -> int:
    """How many values of ``a`` occur in ``b`` (sorted search: numpy's hash-based isin is slow on uint64)."""
    bs = np.sort(b)
    i = np.minimum(np.searchsorted(bs, a), len(bs) - 1)
    return int(np.count_nonzero(bs[i] == a))


def hash_matches(hg, hp):
    """``(gt rows, their prediction rows)`` with equal 64-bit hashes (``hg``, ``hp``: uint64, one per row), the GT
    rows ascending; None when one side holds a hash twice (a duplicate key, or a collision for the caller to settle).

    One ``np.sort`` of both sides (numpy sorts uint64 with SIMD; ``argsort`` is about 15x slower): each hash keeps
    its top bits, then a side bit (GT 0, prediction 1), then its row, so a GT row and its prediction end up side by
    side. A match on the top bits is kept when the whole hashes are equal; top bits that repeat on one side (rare)
    take the exact path (``argsort`` of the whole hashes). Where the compiled kernels are built,
    :func:`hpe_cli.native.hash_pairs` finds the same pairs (one table per cache-sized bucket, no sort).
    """

    fast = hash_pairs(hg, hp)
    if fast is not None:
        return fast if fast is not False else None
    ng = len(hg)
    bits = max(1, int(max(ng, len(hp))).bit_length())
    low = np.uint64((1 << bits) - 1)
    top = ~np.uint64((1 << (bits + 1)) - 1)
    packed = np.empty(ng + len(hp), dtype=np.uint64)
    np.bitwise_and(hg, top, out=packed[:ng])
    np.bitwise_and(hp, top, out=packed[ng:])
    packed[:ng] |= np.arange(ng, dtype=np.uint64)
    packed[ng:] |= np.arange(len(hp), dtype=np.uint64) | np.uint64(1 << bits)
    packed.sort()
    t = packed >> np.uint64(bits)  # top bits and side bit
    same_top = (t[1:] >> np.uint64(1)) == (t[:-1] >> np.uint64(1))
    if (same_top & (t[1:] == t[:-1])).any():  # top bits twice on one side: the whole hashes decide
        return _exact_matches(hg, hp)
    i = np.flatnonzero(same_top)  # a GT row (side bit 0 sorts first) next to a prediction
    gi = (packed[i] & low).astype(np.intp)
    pi = (packed[i + 1] & low).astype(np.intp)
    hit = hg[gi] == hp[pi]  # the whole hashes (a top-bits match of another key is no match)
    pos = np.full(ng, -1, dtype=np.intp)
    pos[gi[hit]] = pi[hit]  # in GT order
    gi = np.flatnonzero(pos >= 0)
    return gi, pos[gi]


def _exact_matches(hg, hp):
    """:func:`hash_matches` on the whole hashes (``argsort``)."""
    op = np.argsort(hp)
    sp = hp[op]
    og = np.argsort(hg)
    sg = hg[og]
    if (sp[1:] == sp[:-1]).any() or (sg[1:] == sg[:-1]).any():
        return None
    at = np.minimum(np.searchsorted(sp, sg), len(sp) - 1)
    hit = sp[at] == sg
    pos = np.full(len(hg), -1, dtype=np.intp)
    pos[og[hit]] = op[at[hit]]
    gi = np.flatnonzero(pos >= 0)
    return gi, pos[gi]


def partitions_for(n_rows: int, partition_rows: int) -> int:
    return int(min(MAX_PARTITIONS, max(1, math.ceil(n_rows / max(1, partition_rows)))))


def estimate_rows(src) -> int:
    """Rows of a table: its own count when the reader knows it, else from the file size (~30 bytes a row)."""
    if getattr(src, "num_rows", None) is not None:
        return int(src.num_rows)
    try:
        return int(os.path.getsize(src.path) // 30) if os.path.isfile(src.path) else 1
    except OSError:
        return 1


class _SideSpill:
    """The partition files of one side (one Arrow IPC file a partition: a partition is read back whole, and
    only its own pages are mapped while it is)."""

    def __init__(self, folder, name, reader, K):
        self.folder, self.name, self.reader, self.K = folder, name, reader, K
        self.writers: list = [None] * K
        self.schema = None
        self.stem_differs: set = set()  # key columns with a row whose file stem is not its text

    @staticmethod
    def _partitioned(c, per, part, K):
        """``(record batch of the chunk's rows in stable partition order, partition bounds)``: each column moved once, by
        the compiled counting sort where it is built (:func:`hpe_cli.native.partition_rows`,
        :func:`~hpe_cli.native.partition_strings`), else by a stable ``argsort`` of ``part`` and a take (the
        same rows)."""

        # angles as written are enough: the matrices are rebuilt from them on the scoring threads (the same
        # function on the same numbers: the same bits), which halves what goes to disk and back
        lean = c.raw is not None and c.dist is None
        fixed = {} if lean else {f"{_PFX}c{k}": np.asarray(c.canonical[k], dtype=np.float64) for k in range(9)}
        for j, (hx, _) in enumerate(per.values()):  # the stem hashes are computed again where needed (rare)
            fixed[f"{_PFX}hx{j}"] = hx
        fixed[f"{_PFX}ok"] = c.ok
        if c.raw is not None:  # one (n, 3) block: read back as a view, no column_stack
            fixed[f"{_PFX}raw"] = np.ascontiguousarray(c.raw, dtype=np.float64)
        if c.dist is not None:
            fixed[f"{_PFX}dist"] = c.dist
        fixed[f"{_PFX}line"] = c.lines
        moved = partition_rows(part, K, list(fixed.values()))
        order = None
        if moved is None:
            order = np.argsort(part, kind="stable")
            bounds = np.searchsorted(part[order], np.arange(K + 1))
            moved = (bounds, [v[order] for v in fixed.values()])
        bounds, arrays = moved
        cols = dict(zip(fixed, arrays))
        if f"{_PFX}raw" in cols:
            raw = numpy_to_arrow(cols[f"{_PFX}raw"].reshape(-1))
            cols[f"{_PFX}raw"] = pa.FixedSizeListArray.from_arrays(raw, 3)
        if c.reasons is None:  # every row usable: n empty strings, built from their (all-zero) offsets
            reason = pa.Array.from_buffers(
                pa.string(), c.n, [None, pa.py_buffer(np.zeros(c.n + 1, np.int32)), pa.py_buffer(b"")]
            )
        else:
            order = np.argsort(part, kind="stable") if order is None else order
            reason = pa.array(c.reasons[order].astype(str), pa.string())
        names = list(cols)
        cols = (
            {n: cols[n] for n in names[: names.index(f"{_PFX}ok") + 1]}
            | {f"{_PFX}reason": reason}
            | {n: cols[n] for n in names[names.index(f"{_PFX}ok") + 1 :]}
        )  # the columns in their order of before (the schema of the files)
        if c.keys is not None:
            for name in c.keys.column_names:
                col = c.keys.column(name)
                col = col.combine_chunks() if isinstance(col, pa.ChunkedArray) else col
                col = col.cast(col.type.value_type) if pa.types.is_dictionary(col.type) else col
                moved_col = partition_strings(part, K, col)
                if moved_col is None:
                    order = np.argsort(part, kind="stable") if order is None else order
                    moved_col = col.take(numpy_to_arrow(order))
                cols[name] = moved_col
        # one record batch from the buffers: pa.table would import pandas (0.3 s) for numpy columns
        return pa.RecordBatch.from_arrays([numpy_to_arrow(v) for v in cols.values()], names=list(cols)), bounds

    def prepare(self, c, keys):
        """``(record batch of the chunk's rows sorted by partition, partition bounds, key columns whose stems differ)``:
        the work of :meth:`add` that needs no shared state (the reader runs it on its label threads)."""

        if not c.n:
            return None
        h, per = key_hashes(c.keys, keys)
        # a key whose stems are its texts everywhere needs no count
        differs = {j for j, (hx, hs) in enumerate(per.values()) if hx is not hs and bool((hx != hs).any())}
        # partition numbers < MAX_PARTITIONS fit int16, whose stable sort is a radix sort
        K = np.uint64(self.K)
        # h % K, written with // (numpy divides by a scalar with libdivide: 10x faster than its %)
        part = (h - (h // K) * K).astype(np.int16) if self.K > 1 else np.zeros(c.n, dtype=np.int16)
        t, bounds = self._partitioned(c, per, part, self.K)
        return t, bounds, differs  # each partition a zero-copy slice

    def add(self, c, keys):

        prepared = c.prepared if c.prepared is not None else self.prepare(c, keys)
        if prepared is None:
            return
        t, bounds, differs = prepared
        self.stem_differs |= differs
        if self.schema is None:
            self.schema = t.schema
        elif t.schema != self.schema:
            t = t.cast(self.schema)
        for k in range(self.K):
            a, b = int(bounds[k]), int(bounds[k + 1])
            if a == b:
                continue
            if self.writers[k] is None:
                self.writers[k] = pa.ipc.new_file(self._path(k), self.schema)
            self.writers[k].write_batch(t.slice(a, b - a))

    def _path(self, k):
        return os.path.join(self.folder, f"{self.name}_{k:04d}.arrow")

    def close(self):
        for w in self.writers:
            if w is not None:
                w.close()
        self.writers = [None] * self.K

    def release(self, k) -> None:
        """Remove partition ``k``'s file once it is read for the last time: its memory map keeps the data for the
        arrays that view it, and the disk's space and dirty pages go now, while the run goes on, not all at its end
        (at 30M pairs the folder's removal took 1.9 s of wall time). Where an open file cannot be removed
        (Windows), :meth:`Partitions.cleanup` does it."""
        try:
            os.unlink(self._path(k))
        except OSError:
            pass

    def table(self, k):
        """Partition ``k`` as a pyarrow Table (memory-mapped), or None when it holds no row."""

        p = self._path(k)
        if not os.path.exists(p):
            return None
        return pa.ipc.open_file(pa.memory_map(p)).read_all()

    def side(self, k, empty_keys):
        """Partition ``k`` as a :class:`~hpe_cli.pipelines.evaluate.sides.Side` (empty when it holds no row)."""

        r = self.reader
        t = self.table(k)
        if t is None:
            z = np.zeros(0)
            side = Side(
                r.path,
                r.system,
                r.mode,
                [z] * 9,
                np.zeros(0, dtype=bool),
                None,
                empty_keys,
                np.zeros(0, dtype=object) if r.by else None,
                r.columns,
                np.zeros(0, dtype=np.int64),
                [],
            )
        else:

            def col(name):
                c = t.column(name)
                return _bools(c) if pa.types.is_boolean(c.type) else arrow_to_numpy(c)

            rc = t.column(f"{_PFX}reason")
            # a reason written in any row: its chunk holds text bytes (every row usable: none, no scan)
            text = any(ch.buffers()[2] is not None and ch.buffers()[2].size for ch in rc.chunks)
            has_reasons = False
            if len(rc) and text:
                import pyarrow.compute as pc  # lazy: start-up (0.06 s; only sides with rows set aside get here)

                has_reasons = bool(pc.max(pc.utf8_length(rc)).as_py() or 0)
            reasons = rc.to_numpy(zero_copy_only=False).astype(object) if has_reasons else None
            keys = t.select([n for n in t.column_names if not n.startswith(_PFX)])
            # one chunk, copied off the memory map: the mapped file leaves memory once the side is built
            keys = keys.select(r.keep).combine_chunks() if r.keep else None
            by = keys.column(r.by).to_numpy(zero_copy_only=False) if r.by else None
            lean = f"{_PFX}c0" not in t.column_names
            side = Side(
                r.path,
                r.system,
                r.mode,
                None if lean else [col(f"{_PFX}c{i}") for i in range(9)],
                col(f"{_PFX}ok"),
                reasons,
                keys,
                by,
                r.columns,
                col(f"{_PFX}line"),
                [],
            )
            if f"{_PFX}raw" in t.column_names:
                raw = t.column(f"{_PFX}raw").combine_chunks()
                side.raw = arrow_to_numpy(raw.values if raw.offset == 0 else raw.flatten()).reshape(-1, 3)
            if f"{_PFX}dist" in t.column_names:
                side.dist = col(f"{_PFX}dist")
            side.hashes = {}
            for j in range(len(r.keep)):
                if f"{_PFX}hx{j}" in t.column_names:
                    hx = col(f"{_PFX}hx{j}")  # a column whose stems are its texts in every row: hs is hx
                    side.hashes[j] = (hx, stem_hashes(keys.column(r.keep[j])) if j in self.stem_differs else hx)
        side.image_dir, side.unit = r.image_dir, r.unit
        return side


class _LockedProgress:
    """A progress bar updated from two threads (one lock: no count lost)."""

    def __init__(self, bar):
        self.bar, self.lock = bar, threading.Lock()

    def update(self, n):
        with self.lock:
            self.bar.update(n)


class Partitions:
    """Both sides written to ``K`` partition files each; :meth:`sides` gives one partition at a time."""

    def __init__(self, gr, pr, keys, partition_rows=None):
        self.gr, self.pr, self.keys = gr, pr, list(keys)
        rows = max(estimate_rows(gr.src), estimate_rows(pr.src))
        self.K = partitions_for(rows, partition_rows or PARTITION_ROWS)
        self.folder = tempfile.mkdtemp(prefix="hpe_eval_join_")
        self.g, self.p = _SideSpill(self.folder, "gt", gr, self.K), _SideSpill(self.folder, "pred", pr, self.K)

    def fill(self):
        """Write both sides' partition files: side by side (the predictions on a thread of their own) when the
        readers have more than one thread, else one after the other. The files are the same either way (each
        side's chunks are written in file order), and so is the error raised: the ground truth's if it has one
        (it is read to its end, as when read first), else the predictions'."""
        try:
            if min(self.gr.threads, self.pr.threads) < 2:
                self._fill_side(self.g, self.gr, None)
                self._fill_side(self.p, self.pr, None)
                return self
            stop = threading.Event()
            bars = [r.progress for r in (self.gr, self.pr)]
            for r in (self.gr, self.pr):  # both threads count rows on the one bar
                r.progress = _LockedProgress(r.progress) if r.progress is not None else None
            with ThreadPoolExecutor(1, thread_name_prefix="hpe-evaluate-spill") as ex:
                pred = ex.submit(self._fill_side, self.p, self.pr, stop)
                try:
                    self._fill_side(self.g, self.gr, None)
                except BaseException:
                    stop.set()  # the predictions' thread stops at its next chunk (the pool waits for it)
                    raise
                finally:
                    ex.shutdown(wait=True)
                    self.gr.progress, self.pr.progress = bars
            pred.result()
        except BaseException:
            self.cleanup()
            raise
        return self

    def _fill_side(self, spill, reader, stop):
        reader.matrices = False  # angles are kept as written: their matrices are built when scored
        reader.group_rows = GROUP_ROWS  # fewer, larger chunks: less per-chunk work and fewer record batches
        reader.prepare = lambda c: spill.prepare(c, self.keys)  # on the label threads
        with closing(reader.chunks()) as chunks:  # an error stops the label threads at once
            for c in chunks:
                if stop is not None and stop.is_set():
                    return
                spill.add(c, self.keys)
        spill.close()

    def _empty_keys(self, reader, spill, other):

        schema = spill.schema or other.schema
        fields = [
            schema.field(c) if schema is not None and c in schema.names else pa.field(c, pa.string())
            for c in reader.keep
        ]
        schema = pa.schema(fields)
        return pa.Table.from_arrays([pa.nulls(0, f.type) for f in schema], schema=schema)  # empty_table imports pandas

    def sides(self, k, last: bool = False):
        """Partition ``k`` of both sides; ``last``: no pass reads it again, so its files are removed as soon as
        they are mapped (:meth:`_SideSpill.release`)."""
        out = (
            self.g.side(k, self._empty_keys(self.gr, self.g, self.p)),
            self.p.side(k, self._empty_keys(self.pr, self.p, self.g)),
        )
        if last:
            self.g.release(k)
            self.p.release(k)
        return out

    def stem_columns(self) -> set:
        """Key columns compared on file stems, decided over all partitions as the in-memory join decides
        (:func:`~hpe_cli.pipelines.evaluate.join._key_codes`: stems when they match more GT rows than the
        text as written), counted on the 64-bit hashes written with each row."""

        def text_key(schema, k):
            t = schema.field(k).type
            return pa.types.is_dictionary(t) and t.value_type or t

        if self.g.schema is None or self.p.schema is None:
            return set()
        tally = {k: [0, 0, 0, 0] for k in self.keys}  # exact matches, stem matches, gt rows, pred rows
        check = [
            j
            for j, k in enumerate(self.keys)
            if (j in self.g.stem_differs or j in self.p.stem_differs)
            and (
                text_key(self.g.schema, k) != text_key(self.p.schema, k)
                or pa.types.is_string(text_key(self.g.schema, k))
                or pa.types.is_large_string(text_key(self.g.schema, k))
            )
        ]
        for i in range(self.K if check else 0):
            tg, tp = self.g.table(i), self.p.table(i)
            n_g, n_p = (tg.num_rows if tg is not None else 0), (tp.num_rows if tp is not None else 0)
            for j in check:
                t = tally[self.keys[j]]
                t[2] += n_g
                t[3] += n_p
                if not n_g or not n_p:
                    continue
                exact = _count_in(arrow_to_numpy(tg.column(f"{_PFX}hx{j}")), arrow_to_numpy(tp.column(f"{_PFX}hx{j}")))
                t[0] += exact
                t[1] += (
                    exact
                    if exact == min(n_g, n_p)
                    else _count_in(stem_hashes(tg.column(self.keys[j])), stem_hashes(tp.column(self.keys[j])))
                )
        return {k for k, (ex, st, ng, npr) in tally.items() if ex < min(ng, npr) and st > ex}

    def codes(self, gt, pred, stems):
        """The pairs of one partition (:class:`~hpe_cli.pipelines.evaluate.join.Matched`) from the key hashes, every
        match verified on the keys themselves; None (use the string join) when a key is not text on both sides,
        when one side has equal hashes twice (a duplicate, which the string join names) or when a match is a hash
        collision."""

        def is_text(schema, k):
            return pa.types.is_string(schema.field(k).type)

        if not (gt.n and pred.n) or not all(is_text(self.g.schema, k) and is_text(self.p.schema, k) for k in self.keys):
            return None
        if len(getattr(gt, "hashes", {})) < len(self.keys) or len(getattr(pred, "hashes", {})) < len(self.keys):
            return None
        w = [1 if k in stems else 0 for k in self.keys]
        if len(self.keys) == 1:  # combine_key_hash(0, h) is h
            hg, hp = gt.hashes[0][w[0]], pred.hashes[0][w[0]]
        else:
            hg, hp = np.zeros(gt.n, dtype=np.uint64), np.zeros(pred.n, dtype=np.uint64)
            for j in range(len(self.keys)):
                hg = combine_key_hash(hg, gt.hashes[j][w[j]])
                hp = combine_key_hash(hp, pred.hashes[j][w[j]])
        # the pairs proposed by equal hashes (GT rows ascending), then verified on the keys below
        matched = hash_matches(hg, hp)
        if matched is None:
            return None  # equal hashes on one side: a duplicate key (named by the string join) or a collision
        gi, pi = matched
        for k in self.keys:
            a, b = gt.keys.column(k), pred.keys.column(k)
            a, b = (_one_array(a), _one_array(b))
            if k not in stems:  # the bytes compared at the pairs straight off the Arrow buffers (no gather)
                bad = first_unequal(a, None if len(gi) == gt.n else gi, b, pi)
                if bad is not None:
                    if bad >= 0:
                        return None
                    continue
            import pyarrow.compute as pc  # lazy: start-up (0.06 s; keys compared by the kernels need none)

            # every GT row matched (the usual case): gi is 0..n-1, the column itself
            a = a if len(gi) == gt.n else a.take(numpy_to_arrow(gi))
            b = b.take(numpy_to_arrow(pi))
            if k in stems:
                a, b = file_stems(a), file_stems(b)
            if len(gi) and not pc.all(pc.equal(a, b)).as_py():
                return None
        return Matched(gi, pi)

    def cleanup(self):
        for s in (self.g, self.p):
            try:
                s.close()
            except Exception:  # noqa: BLE001, S110 - closing after a failure: the folder goes anyway
                pass
        shutil.rmtree(self.folder, ignore_errors=True)
