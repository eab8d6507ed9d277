"""opal23-align's Karcher mean over every pair of a run, estimated from a spill (memory flat in the pairs).

opal23's ``align_predictions`` (pcr-upm/opal23_headpose@78c0c45 test/evaluator.py:95-129) turns every prediction by
the inverse of one Karcher mean over the whole test set, so no chunk can be scored by it before every pair has been
seen. The scoring pass therefore spills, chunk by chunk and in scoring order, the unit quaternions of ``P_i G_i^T``
within 90 degrees of the identity (:class:`KarcherSpill`, what the mean is taken over) and what opal23-align reads
of each chunk (:class:`DeferredRows`, :func:`hpe_cli.metrics.protocols.opal23_align_inputs`: the quaternions of
opal23's rotations of both sides, the GT's Euler angles, two masks). Once the pass is over, the mean is estimated
and the spilled chunks are scored with it, in the same chunks and order as the other protocols: the same per-row
numbers and the same sums as scoring them inline with the mean known in advance, without reading and decoding both
input files a second time.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import numpy as np

from ...metrics import peer_angles as pa_
from ...metrics.protocols import OPAL23_ALIGN_INPUTS, opal23_align_inputs, opal23_align_rows, opal23_mats
from ..pools import in_order

#: the protocol whose score waits for the mean
OPAL23_ALIGN = "opal23-align"

#: rows of the spill read at a time by the mean's passes (8 MB, a multiple of
#: :data:`~hpe_cli.metrics.peer_angles.KARCHER_PIECE`, so the same pieces and the same mean as any other multiple):
#: the passes run after the scoring pass, whose freed memory malloc keeps, so what they read adds to the peak
KARCHER_CHUNK = 1 << 18


def deferred_protocols(protocols, align: str) -> tuple:
    """The protocols of a run scored after its pass (:data:`OPAL23_ALIGN` when asked; with ``--align mean``
    every protocol waits for that offset anyway, and the opal23 mean is estimated in the same early pass)."""
    return (OPAL23_ALIGN,) if OPAL23_ALIGN in protocols and align != "mean" else ()


def opal23_chunk(pair) -> tuple:
    """``(near quaternions (M, 4), opal23_align_inputs)`` of one chunk's :class:`PosePair` (a ``compute_rows``
    hook: opal23's matrices and the GT's Euler angles are shared with the opal23 protocol's)."""
    P, G, _ = opal23_mats(pair)
    deltas, near = pa_.opal23_near_quats(G, P)
    return deltas, opal23_align_inputs(pair, near)


class _Rows:
    """Rows of ``width`` float64 in an open binary file, read on indexing (``rows[a:b]``, ``rows[i]``): a spill
    as an array-like whose pages do not stay mapped (a ``np.memmap`` would add them to the process's peak)."""

    def __init__(self, f, n: int, width: int):
        self.f, self.n, self.width = f, int(n), int(width)
        self.ndim = 2

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k):
        if isinstance(k, slice):
            a, b, _ = k.indices(self.n)
            b = max(a, b)
        else:
            a, b = int(k), int(k) + 1
        self.f.seek(a * self.width * 8)
        out = np.fromfile(self.f, dtype=np.float64, count=(b - a) * self.width).reshape(-1, self.width)
        return out if isinstance(k, slice) else out[0]


class KarcherSpill:
    """The near quaternions of every chunk, in order, in a temporary file; :meth:`mean` is opal23's mean.

    The peer starts its iteration at the first near row of its file: the near row with the smallest GT line
    is remembered whatever order the chunks come in (the key join scores partitions in hash order).
    """

    def __init__(self):
        fd, self.path = tempfile.mkstemp(prefix="hpe_eval_opal23_", suffix=".bin")
        self.f = os.fdopen(fd, "wb")
        self.first, self.written = (np.iinfo(np.int64).max, 0), 0

    def add(self, deltas, near, lines) -> None:
        """One chunk's near quaternions ``(M, 4)``, its near mask ``(n,)`` and its GT lines ``(n,)``."""
        if near.any():
            ln = lines[near]
            j = int(np.argmin(ln))
            if ln[j] < self.first[0]:
                self.first = (int(ln[j]), self.written + j)
        self.written += len(deltas)
        np.ascontiguousarray(deltas).tofile(self.f)

    def mean(self, mapper=map) -> np.ndarray:
        """opal23's Karcher mean (3, 3) over every row added (read back piece by piece)."""
        self.f.close()
        size = os.path.getsize(self.path)
        with open(self.path, "rb") as f:  # read piece by piece: a memory map's pages would count in the peak
            return pa_.opal23_karcher(_Rows(f, size // 32, 4), chunk=KARCHER_CHUNK, start=self.first[1], mapper=mapper)

    def close(self) -> None:
        self.f.close()
        if os.path.exists(self.path):
            os.unlink(self.path)


def _as_bytes(a) -> np.ndarray:
    a = np.ascontiguousarray(a)
    return a.view(np.uint8).reshape(-1)


class DeferredRows:
    """Each chunk's :func:`opal23_chunk` inputs and grouping codes, spilled in scoring order, read back in it.

    A chunk's arrays are written one after the other; what is remembered in memory is one small record per
    chunk (the arrays' names, dtypes and shapes).
    """

    def __init__(self):
        self.folder = tempfile.mkdtemp(prefix="hpe_eval_deferred_")
        self.path = os.path.join(self.folder, "chunks.bin")
        self.f = open(self.path, "wb")  # noqa: SIM115 -- closed in read() / close()
        self.karcher = KarcherSpill()
        self.chunks: list = []

    def add(self, extra, lines, codes: dict) -> None:
        """One scored chunk: the hook's ``(deltas, inputs)``, its GT lines and its grouping codes (``by``,
        ``bins``: int arrays, or None)."""
        deltas, inputs = extra
        self.karcher.add(deltas, inputs["near"], lines)
        meta = []
        for name, a in [(k, inputs[k]) for k in OPAL23_ALIGN_INPUTS] + [(k, v) for k, v in codes.items()]:
            if a is None:
                meta.append((name, None, None))
                continue
            a = np.asarray(a)
            meta.append((name, a.dtype.str, a.shape))
            _as_bytes(a).tofile(self.f)
        self.chunks.append(meta)

    def read(self):
        """``(inputs, codes)`` of every chunk, in the order they were added."""
        self.f.close()
        with open(self.path, "rb") as f:
            for meta in self.chunks:
                got = {}
                for name, dt, shape in meta:
                    got[name] = (
                        None if dt is None else np.fromfile(f, dtype=dt, count=int(np.prod(shape))).reshape(shape)
                    )
                inputs = {k: got[k] for k in OPAL23_ALIGN_INPUTS}
                yield inputs, {k: v for k, v in got.items() if k not in inputs}

    def close(self) -> None:
        self.f.close()
        self.karcher.close()
        shutil.rmtree(self.folder, ignore_errors=True)


def score_deferred(spill: DeferredRows, acc, pool, threads: int) -> np.ndarray:
    """Estimate opal23's mean, then add opal23-align's sums of every spilled chunk to ``acc`` in order (each
    chunk scored on ``pool``). Returns the mean."""
    mean = spill.karcher.mean(mapper=pool.map)

    def work(item):
        inputs, codes = item
        rows = opal23_align_rows(inputs, mean)
        return acc.protocol_partial(OPAL23_ALIGN, rows, codes)

    for part in in_order(pool, work, spill.read(), ahead=threads):
        acc.merge_protocol(part)
    return mean
