"""``hpe evaluate``'s inputs: each side opened once and read in chunks.

:func:`open_side` opens a table once (a :class:`~hpe_cli.io.label_source.LabelSource`: its system resolved,
its label columns found); each pass makes a :class:`SideReader` of it, whose :meth:`~SideReader.chunks` are
:class:`Chunk` s: canonical matrices (nine float64 columns), usability, the angles as written (when the side
holds angles), key and ``--by`` columns, each row's line. :func:`read_side` reads a side whole into a
:class:`Side` (the in-memory join's input). The pairing itself is in :mod:`.join`, :mod:`.lockstep` and
:mod:`.spill`.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from ...io import MATRIX_COLS, batch_rotations
from ...io.key_hash import string_hashes
from ...io.label_source import LabelSource, check_mode
from ...io.labels import angle_columns, is_native, value_columns
from ...io.readers import LINE_COL
from ...io.system_meta import resolve_system
from ...io.table_source import plain_numpy
from ...metrics.align import project_to_so3_batch
from ...rotation import soa
from ..pools import in_order

#: threads that turn each side's decoded batches into labels
LABEL_THREADS = 2


@dataclass
class Side:
    """One input table, read: canonical matrices, usability, keys."""

    path: object
    system: object
    mode: str
    canonical: list  # 9 arrays (N,): the canonical matrix entries, row-major
    ok: np.ndarray  # (N,) bool
    reasons: np.ndarray | None  # (N,) object, '' when usable; None when every row is usable
    keys: object  # pyarrow Table of the key (and --by) columns, or None
    by: np.ndarray | None
    columns: list
    lines: np.ndarray  # (N,) 1-based file line of each row (header = line 1)
    unreadable: list  # rows the reader could not parse: (line, reason)
    raw: np.ndarray | None = None  # (N, 3) the angles as written (degrees), when the side holds angles
    dist: np.ndarray | None = None  # (N,) distance to the nearest rotation (--orthonormalize)
    image_dir: object = None  # folder of a dataset reader whose images sit next to the labels
    unit: str = "line"  # "row" for Parquet
    resolved: object = None  # hpe_cli.io.system_meta.Resolved: the system and where it came from

    @property
    def n(self) -> int:
        return len(self.ok)


def _batch_labels(batch, system, mode, radians, orthonormalize, matrices=True):
    """``(stored soa, ok, reasons, raw angles (n, 3) or None, distance (n,) or None)`` of one batch.

    Angle columns are kept as written (``raw``): the raw-angle protocols compare
    them. With ``orthonormalize`` a matrix that is not a rotation (a network's
    raw output, e.g. TriNet's vectors) is replaced by its nearest rotation
    (SVD, det +1) and ``distance`` is ``||M - R||_F``.
    """

    n = batch.num_rows
    native = is_native(system, batch.schema.names)
    if mode == "angles":
        cols, ok, reasons = angle_columns(batch, system, radians)
        raw = np.stack([np.where(ok, c, 0.0) for c in cols], axis=-1)
        return (stored_of_angles(system, raw) if matrices else None), ok, reasons, raw, None
    if orthonormalize and (mode == "matrix" or system.storage_kind == "matrix"):
        names = system.value_columns if (native and system.storage_kind == "matrix") else None
        if names is None:
            names = MATRIX_COLS
        cols, ok, reasons = value_columns(batch, names)
        M = np.stack([np.where(ok, c, 0.0) for c in cols], axis=-1).reshape(n, 3, 3)
        R, dist = project_to_so3_batch(M)
        bad = ok & ~np.isfinite(dist)
        if bad.any():
            reasons = np.full(n, "", dtype=object) if reasons is None else reasons
            reasons[bad] = "matrix has no nearest rotation (rank < 2)"
            ok &= ~bad
        R[~ok] = np.eye(3)
        return [[R[:, i, j] for j in range(3)] for i in range(3)], ok, reasons, None, np.where(ok, dist, np.nan)
    X, ok, rs = batch_rotations(batch, system, mode, radians)
    return X, ok, rs, None, None


def stored_of_angles(system, raw) -> list:
    """The stored matrices (nested list of ``(n,)`` arrays) of angles ``(n, 3)`` in degrees written in ``system``:
    the reader's computation, and the key join's when it rebuilds them from the angles it kept."""
    n = len(raw)
    X = system.soa_from_angles(raw[:, 0], raw[:, 1], raw[:, 2])
    return [
        [np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)) if np.ndim(v) == 0 else v for v in row] for row in X
    ]


def _stem_key_hook(batch):
    """HOOK (joins by key): a dataset reader with ``file`` but no ``image`` (the ``.mat`` folder reader) gets
    ``image`` = the file stem, so predictions keyed by image name join. Remove once the reader provides it."""
    names = batch.schema.names
    if "image" in names or "file" not in names:
        return batch
    stem = file_stems(batch.column(names.index("file")))
    return pa.RecordBatch.from_arrays(list(batch.columns) + [stem], names=names + ["image"])


def file_stems(arr):
    """The file stems of a text array: what is left once the folders and the last suffix are removed."""
    import pyarrow.compute as pc  # lazy: start-up (0.06 s; the streamed run with equal keys needs none)

    return pc.replace_substring_regex(pc.cast(arr, pa.string()), r"^.*[\\/]|\.[^.\\/]*$", "")


@dataclass
class Chunk:
    """One batch of one side."""

    canonical: list | None  # 9 arrays (n,): canonical matrix entries, row-major (None: rebuilt from ``raw``)
    ok: np.ndarray
    reasons: np.ndarray | None
    raw: np.ndarray | None
    dist: np.ndarray | None
    keys: object  # pyarrow Table of the key (and --by) columns, or None
    by: np.ndarray | None
    lines: np.ndarray
    prepared: object = None  # what the reader's ``prepare`` made of the chunk on the label threads

    @property
    def n(self) -> int:
        return len(self.ok)

    def slice(self, a: int, b: int) -> Chunk:
        def cut(x):
            return None if x is None else x[a:b]

        return Chunk(
            None if self.canonical is None else [c[a:b] for c in self.canonical],
            self.ok[a:b],
            cut(self.reasons),
            cut(self.raw),
            cut(self.dist),
            None if self.keys is None else self.keys.slice(a, b - a),
            cut(self.by),
            self.lines[a:b],
        )


def key_text(col):
    """A key column as one Arrow string array (chunks combined, dictionaries decoded, other types cast)."""
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_dictionary(col.type):
        col = col.cast(col.type.value_type)
    if pa.types.is_string(col.type):
        return col
    import pyarrow.compute as pc  # lazy: start-up (0.06 s; text keys need none)

    return pc.cast(col, pa.string())


def combine_key_hash(h: np.ndarray, column_hash: np.ndarray) -> np.ndarray:
    """Fold one key column's 64-bit hashes into the running hash of the key columns before it."""
    with np.errstate(over="ignore"):
        return h * np.uint64(1_000_003) ^ column_hash


def keys_hash(table, keys) -> np.ndarray:
    """One uint64 per row of the key columns (text as written; see :func:`hpe_cli.io.key_hash.string_hashes`)."""

    h = np.zeros(table.num_rows, dtype=np.uint64)
    for k in keys:
        h = combine_key_hash(h, string_hashes(key_text(table.column(k)), stems=False)[0])
    return h


def side_columns(table) -> list:
    """The columns of one side as the join sees them: a ``.mat`` folder's rows also have ``image`` (the file
    stem, see :func:`_stem_key_hook`)."""
    columns = list(table.columns)
    if "file" in columns and "image" not in columns and bool(table.dataset):
        columns.append("image")
    return columns


def open_side(table, system, use: str, role: str):
    """One input of ``hpe evaluate``, its table opened once (``open_table(path, batch_size, with_lines=True)``),
    as a :class:`~hpe_cli.io.label_source.LabelSource`: its system resolved, its label columns found.

    ``system`` is the ``--{role}-system`` option (the file's own system wins; a dataset format's labels are
    converted to it), ``use`` the ``--columns`` choice (``"auto"``: the system's own value columns, then
    angles, then ``r00..r22``).
    """
    resolved = resolve_system(table, system, default=None, option_name=f"--{role}-system", option_is_output=True)
    # the columns as evaluate reads them (a dataset's file stems count as its image key)
    return LabelSource(table, resolved, check_mode(side_columns(table), table.path, resolved.system, use))


class SideReader:
    """One input side, opened once (:class:`~hpe_cli.io.label_source.LabelSource`): :meth:`chunks` streams it.

    Each pass (the scoring pass, a global estimate's pass, the spill) makes a reader of the same source: the
    table is read again, its system and label columns are not decided again.
    """

    def __init__(
        self, source, keys, by, radians: bool, progress=None, orthonormalize=False, extra=(), threads=LABEL_THREADS
    ):
        self.source = source
        self.src = src = source.table
        self.resolved = source.resolved
        self.system = source.system
        self.path = src.path
        self.columns = columns = side_columns(src)
        self.dataset_stem = "image" in columns and "image" not in src.columns
        self.mode = source.mode
        self.keep = [
            c
            for c in dict.fromkeys(list(keys or ()) + ([by] if by and by in columns else []) + list(extra))
            if c in columns
        ]  # extra: carried (face boxes)
        self.by = by if by and by in columns else None
        self.radians, self.progress, self.orthonormalize = radians, progress, orthonormalize
        self.threads = max(1, int(threads))
        self.unreadable: list = []
        self.n = 0
        #: False: a side that holds angles hands them over without their matrices (``canonical`` None: the key
        #: join keeps the angles and the scoring threads rebuild the matrices from them, the same bits)
        self.matrices = True
        #: a function of each :class:`Chunk` run on the label threads (its result in ``Chunk.prepared``)
        self.prepare = None
        #: > 0: consecutive batches put together into chunks of at least this many rows (the key join's spill, whose
        #: per-chunk work is the same whatever the rows; the streamed pairing keeps the batches as read)
        self.group_rows = 0
        self.image_dir = src.path if self.dataset_stem else None
        #: how a row is named in messages: Parquet "row N" (1-based), text "line N" (header = line 1)
        self.unit = "row" if src.kind == "parquet" else "line"

    def chunks(self):
        """Yield one :class:`Chunk` per batch of the table, in file order.

        The batches are decoded here, one after the other; their labels (matrices from the angles, checks) are
        computed on ``threads`` threads (:data:`LABEL_THREADS` by default), at most that many batches ahead.
        """

        def batches():
            pending: list = []  # batches put together up to group_rows (one labelling, one spill write)
            for batch, bad_rows in self.src.batches_with_rejects():
                self.unreadable += [(r.line, r.reason) for r in bad_rows]
                if not self.group_rows:
                    yield batch
                    continue
                if pending and (batch.schema != pending[0].schema or _has_dictionary(batch)):
                    yield _joined(pending)
                    pending = []
                pending.append(batch)
                if _has_dictionary(batch) or sum(b.num_rows for b in pending) >= self.group_rows:
                    yield _joined(pending)
                    pending = []
            if pending:
                yield _joined(pending)

        pool = ThreadPoolExecutor(self.threads, thread_name_prefix="hpe-evaluate-labels")
        try:
            for chunk in in_order(pool, self._chunk, batches(), ahead=self.threads):
                self.n += chunk.n
                if self.progress is not None:
                    self.progress.update(chunk.n)
                yield chunk
        finally:
            pool.shutdown(wait=True, cancel_futures=True)

    def _chunk(self, batch) -> Chunk:

        if self.dataset_stem:
            batch = _stem_key_hook(batch)
        lines = plain_numpy(batch.column(LINE_COL)).astype(np.int64)
        X, ok, rs, raw, dist = _batch_labels(
            batch, self.system, self.mode, self.radians, self.orthonormalize, self.matrices
        )
        n = batch.num_rows
        canonical = None if X is None else soa.columns(self.system.soa_to_canonical(X), n)
        keys = batch.select(self.keep) if self.keep else None
        by = keys.column(self.by).to_numpy(zero_copy_only=False) if self.by else None
        c = Chunk(canonical, ok, rs, raw, dist, keys, by, lines)
        if self.prepare is not None:
            c.prepared = self.prepare(c)
        return c


def _has_dictionary(batch) -> bool:
    return any(pa.types.is_dictionary(f.type) for f in batch.schema)


def _joined(batches):
    """One record batch of consecutive batches with one schema (their rows in order)."""
    if len(batches) == 1:
        return batches[0]
    (batch,) = pa.Table.from_batches(batches).combine_chunks().to_batches() or [batches[0].slice(0, 0)]
    return batch


def read_side(source, keys, by, radians: bool, progress=None, orthonormalize=False, threads=LABEL_THREADS) -> Side:
    """Read one table whole into a :class:`Side` (for the in-memory key join).

    Each field is gathered as a list of chunk arrays and concatenated (and its
    list freed) one field at a time, so the peak is one field above the data.
    """

    r = SideReader(source, keys, by, radians, progress, orthonormalize, threads=threads)
    parts: dict = {f"c{k}": [] for k in range(9)}
    parts.update(ok=[], reasons=[], raw=[], dist=[], keys=[], by=[], lines=[])
    any_reasons = False
    with closing(r.chunks()) as chunks:  # an error stops the label threads at once
        for c in chunks:
            for k in range(9):
                parts[f"c{k}"].append(c.canonical[k])
            any_reasons |= c.reasons is not None
            for name in ("ok", "reasons", "raw", "dist", "keys", "by", "lines"):
                v = getattr(c, name)
                parts[name].append(np.full(c.n, "", dtype=object) if name == "reasons" and v is None else v)

    def cat(name, empty=None):
        lst, parts[name] = parts[name], None
        if not lst:
            return empty
        if any(x is None for x in lst):
            return None
        return np.concatenate(lst)

    canonical = [cat(f"c{k}", np.zeros(0)) for k in range(9)]
    ok = cat("ok", np.zeros(0, dtype=bool))
    rs_all = cat("reasons") if any_reasons else None
    table = None
    if r.keep:
        if parts["keys"]:
            table = pa.Table.from_batches(parts["keys"])
        else:
            table = pa.schema(
                [r.src.schema.field(c) if c in r.src.schema.names else pa.field(c, pa.string()) for c in r.keep]
            ).empty_table()
    parts["keys"] = None
    by_values = cat("by") if r.by else None
    lines = cat("lines", np.zeros(0, dtype=np.int64))
    side = Side(r.path, r.system, r.mode, canonical, ok, rs_all, table, by_values, r.columns, lines, r.unreadable)
    side.raw = cat("raw")
    side.dist = cat("dist")
    side.image_dir = r.image_dir
    side.unit = r.unit
    side.resolved = r.resolved
    return side
