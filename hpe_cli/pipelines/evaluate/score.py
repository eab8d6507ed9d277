"""Scoring the pairs of ``hpe evaluate``: chunks scored on threads, consumed in order (sums, spill, rows)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pyarrow as pa

from ...io.layout import numpy_to_arrow
from ...metrics.align import remove_offset
from ...metrics.evaluate import compute_rows, yaw_bin_edges
from ...metrics.protocols import PROTOCOLS
from ...metrics.stream import Accumulator
from ...rotation import soa
from ..pools import in_order
from .opal23 import DeferredRows, deferred_protocols, opal23_chunk, score_deferred
from .outputs import Sample, Worst, row_table
from .rejects import stream_rejects
from .sides import Chunk, stored_of_angles

#: threads that score chunks side by side (the reading runs on one more, see ``prefetch``)
SCORE_THREADS = 2
#: rows scored at once (arrays of 64k float64 stay in the caches)
SCORE_ROWS = 65536
#: GT columns carried to the worst rows (with --report) to place and crop their pictures
PLACEMENT = ("bbox_x", "bbox_y", "bbox_w", "bbox_h", "tdx", "tdy", "size")


def take_rows(c: Chunk, idx) -> Chunk:
    """Rows ``idx`` (int array or bool mask) of a chunk."""

    def t(x):
        return None if x is None else x[idx]

    keys = None
    if c.keys is not None:
        keys = c.keys.filter(idx) if np.asarray(idx).dtype == bool else c.keys.take(idx)
    return Chunk(
        None if c.canonical is None else [x[idx] for x in c.canonical],
        c.ok[idx],
        t(c.reasons),
        t(c.raw),
        t(c.dist),
        keys,
        t(c.by),
        c.lines[idx],
    )


def with_canonical(c: Chunk, system) -> Chunk:
    """The chunk with its canonical matrices, rebuilt from the angles as written when the key join's partition
    files kept only those (the reader's own computation on the same numbers: the same bits)."""
    if c.canonical is not None:
        return c

    c.canonical = soa.columns(system.soa_to_canonical(stored_of_angles(system, c.raw)), c.n)
    return c


def with_written(t, p: Chunk):
    """The per-row table with the prediction's angles as written in its file (``pred_written_pitch``...,
    degrees, its own system), for the page's worst rows: beside the angles hpe re-expressed in the GT system."""
    if p.raw is None or "pred_written_pitch" in t.column_names:
        return t

    for k, a in enumerate(("pitch", "yaw", "roll")):
        t = t.append_column(f"pred_written_{a}", numpy_to_arrow(np.ascontiguousarray(p.raw[:, k], dtype=np.float64)))
    return t


def nested(c: Chunk):
    return [[c.canonical[3 * i + j] for j in range(3)] for i in range(3)]


def raw_angles(g: Chunk, p: Chunk, gsys, psys, aligned=False) -> dict:
    raw = {}
    if g.raw is not None:
        raw["gt"] = (gsys, g.raw)
    if p.raw is not None and not aligned:
        raw["pred"] = (psys, p.raw)
    return raw


def count_orthonormalized(counts: dict, p: Chunk) -> None:
    """Add a chunk's ``--orthonormalize`` distances to the run's counts (rows moved, sum and max distance)."""
    if p.dist is not None and len(p.dist):
        counts["orthonormalized"] = counts.get("orthonormalized", 0) + int((p.dist > 1e-6).sum())
        counts["dist_sum"] = counts.get("dist_sum", 0.0) + float(p.dist.sum())
        counts["dist_max"] = max(counts.get("dist_max", 0.0), float(p.dist.max()))


def with_placement(t, g: Chunk, p: Chunk):
    """A chunk's per-row table for the page's worst rows: the face box of each row, which places its picture
    (not in the per-row output), and the prediction's angles as written."""
    for c in PLACEMENT:
        if g.keys is not None and c in g.keys.column_names and c not in t.column_names:
            t = t.append_column(c, g.keys.column(c))
    return with_written(t, p)


class RowWriter:
    """The per-row output, written on its own thread (Parquet encoding releases the GIL) in pieces of about
    ``batch_size`` rows, in the order the tables are added; at most two pieces wait, so memory stays bounded."""

    def __init__(self, writer, batch_size: int):
        self.writer, self.batch_size = writer, batch_size
        self.pending: list = []
        self.writes: list = []
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="hpe-evaluate-write")

    def add(self, table) -> None:
        self.pending.append(table)
        self._flush(self.batch_size)

    def _flush(self, at_least: int) -> None:
        if self.pending and sum(t.num_rows for t in self.pending) >= at_least:
            while len(self.writes) >= 2:
                self.writes.pop(0).result()
            piece = self.pending[0] if len(self.pending) == 1 else pa.concat_tables(self.pending)
            self.writes.append(self.pool.submit(self.writer.write, piece))
            self.pending.clear()

    def finish(self) -> None:
        """Write what is left and wait for every piece (a write's error is raised here)."""
        self._flush(1)
        while self.writes:
            self.writes.pop(0).result()

    def close(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


def score_pairs(s, pairs, rej, gsys, psys, glob, writer, stream: bool):
    """Score every chunk of pairs: accumulate, write rows, keep the worst and a plot sample.

    Chunks are scored on ``s.threads`` threads (:data:`SCORE_THREADS` by default; numpy releases the GIL on
    whole columns) and consumed in input order, so sums, the spill and the
    per-row output are the same as one thread's.
    """

    protos = {k: PROTOCOLS[k] for k in s.protocols}
    edges = yaw_bin_edges(gsys, float(s.options.yaw_bins)) if s.options.yaw_bins else None
    acc = Accumulator(protos, edges, by=bool(s.options.by))
    # the percentiles' second pass reads the spill in parts on these threads (integer counts: any number of them)
    acc.threads = max(1, int(s.threads or SCORE_THREADS))
    before = Accumulator(protos, None, by=False, percentiles=True) if s.options.align == "mean" else None
    worst, sample = Worst(s.options.worst if s.options.html else 0), Sample()
    plotted = bool(s.options.plots or s.options.html)  # the plot sample is drawn by --plots and --report only
    ctx = {"opal23_mean": glob["opal23_mean"]} if "opal23_mean" in glob else {}
    counts = {"pairs": 0, "invalid": 0}
    later = deferred_protocols(s.protocols, s.options.align)  # scored once the pass is over (opal23's mean)
    now = [k for k in s.protocols if k not in later]
    hook = opal23_chunk if later else None
    deferred = DeferredRows() if later else None

    def usable():  # in order, on this thread: the rejects file is written as the rows come
        for g, p in pairs:
            if stream:
                bad = ~(g.ok & p.ok)
                if bad.any():
                    stream_rejects(rej, s, g, p, bad)
                    counts["invalid"] += int(bad.sum())
                    g, p = take_rows(g, ~bad), take_rows(p, ~bad)
            for a in range(0, g.n, SCORE_ROWS):  # cache-sized pieces: numpy is faster on them
                yield g.slice(a, a + SCORE_ROWS), p.slice(a, a + SCORE_ROWS)

    def work(gp):  # on a scoring thread: pure numpy and Arrow, no shared state
        g, p = with_canonical(gp[0], gsys), with_canonical(gp[1], psys)
        P, G = nested(p), nested(g)
        by_values = (g.by if g.by is not None else p.by) if s.options.by else None
        rows_before = None
        if before is not None:
            rows_before = compute_rows(P, G, gsys, s.protocols, raw_angles(g, p, gsys, psys), ctx)
            P = remove_offset(P, glob["Q"])
        rows = compute_rows(P, G, gsys, now, raw_angles(g, p, gsys, psys, aligned=before is not None), ctx, hook)
        table = None
        if writer is not None or worst.n:
            table = row_table(rows, g, p, s.keys, s.options.by, by_values, s.images)
        part, block = acc.partial(rows), (Sample.block(rows) if plotted else None)
        if (
            not s.options.by
        ):  # their sums are in `part`: every protocol's per-row arrays are freed before the chunk's turn
            rows.protocols = {}
        return g, p, rows, rows_before, by_values, table, part, block

    rows_out = RowWriter(writer, s.options.batch_size) if writer is not None else None

    threads = max(1, int(s.threads or SCORE_THREADS))
    pool = ThreadPoolExecutor(threads, thread_name_prefix="hpe-evaluate-score")
    try:
        pieces = usable()
        for g, p, rows, rows_before, by_values, t, part, block in in_order(pool, work, pieces, ahead=threads):
            if rows_before is not None:
                before.add(rows_before)
            counts["pairs"] += rows.n
            count_orthonormalized(counts, p)
            codes = acc.add(rows, by_values, part)
            if deferred is not None:
                deferred.add(rows.extra, g.lines, codes)
            if plotted:
                sample.add(rows, block)
            if rows_out is not None:
                rows_out.add(t)
            if worst.n:
                worst.add(with_placement(t, g, p))
        if rows_out is not None:
            rows_out.finish()
        if deferred is not None:
            score_deferred(deferred, acc, pool, threads)
        rep = acc.report()
        rep_before = before.report() if before is not None else None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if rows_out is not None:
            rows_out.close()
        for it in (locals().get("pieces"), pairs):  # a signal or an error: the readers' threads and temp files go now
            if hasattr(it, "close"):
                it.close()
        acc.close()
        if deferred is not None:
            deferred.close()
        if before is not None:
            before.close()
    return rep, rep_before, counts, worst, sample
