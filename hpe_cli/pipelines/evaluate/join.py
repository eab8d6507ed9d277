"""``hpe evaluate`` inputs: read each side in chunks, pair the two by key (or by position when asked).

Each side is read batch by batch (:class:`SideReader`); a batch becomes a
:class:`Chunk`: canonical matrices (nine float64 columns), usability, the
angles as written (when the side holds angles), key and ``--by`` columns.
Pairing is by key columns only: when both files list the same keys in the same
order the chunks are paired as they stream (memory flat in the number of
pairs, keys verified chunk by chunk); otherwise both sides are partitioned by
a hash of the key on disk and each partition joined here with Arrow dictionary
encoding or verified key hashes (:mod:`hpe_cli.pipelines.evaluate.spill`; :func:`read_side`
+ :func:`join` whole in memory is the reference it is tested against). Row order
is used only with ``--join order`` and equal row counts.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ...errors import HpeError
from ...io import ANGLE_COLS, MATRIX_COLS, batch_rotations, label_mode, open_table
from ...io.key_hash import string_hashes
from ...io.label_source import AUTO, LabelSource
from ...io.labels import is_native, label_columns_fast, value_columns
from ...io.layout import arrow_to_numpy
from ...io.readers import LINE_COL
from ...io.system_meta import resolve_system
from ...io.table_source import plain_numpy
from ...metrics.align import project_to_so3_batch
from ...rotation import soa
from ..pools import in_order

#: key columns tried in order when --key is not given
DEFAULT_KEYS = ("image", "file")
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


def _batch_labels(batch, system, mode, radians, orthonormalize):
    """``(stored soa, ok, reasons, raw angles (n, 3) or None, distance (n,) or None)`` of one batch.

    Angle columns are kept as written (``raw``): the raw-angle protocols compare
    them. With ``orthonormalize`` a matrix that is not a rotation (a network's
    raw output, e.g. TriNet's vectors) is replaced by its nearest rotation
    (SVD, det +1) and ``distance`` is ``||M - R||_F``.
    """

    n = batch.num_rows
    native = is_native(system, batch.schema.names)
    if mode == "angles":
        if native and system.storage_kind == "angles":
            cols, ok, reasons = value_columns(batch, system.value_columns)
            if system.value_units == "radians":
                cols = [c * (180.0 / np.pi) for c in cols]
        else:
            cols, ok, reasons = label_columns_fast(batch, "angles", radians)
        raw = np.stack([np.where(ok, c, 0.0) for c in cols], axis=-1)
        return stored_of_angles(system, raw), ok, reasons, raw, None
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
    f = batch.column(names.index("file"))
    stem = pc.replace_substring_regex(pc.cast(f, pa.string()), r"^.*[\\/]|\.[^.\\/]*$", "")
    return pa.RecordBatch.from_arrays(list(batch.columns) + [stem], names=names + ["image"])


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
    key_hash: np.ndarray | None = None  # (n,) uint64 of the key columns, when the reader was asked for them

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
            cut(self.key_hash),
        )


def key_text(col):
    """A key column as one Arrow string array (chunks combined, dictionaries decoded, other types cast)."""

    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_dictionary(col.type):
        col = col.cast(col.type.value_type)
    return col if pa.types.is_string(col.type) else pc.cast(col, pa.string())


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


def open_side(path, system, use: str, role: str, batch_size: int):
    """One input of ``hpe evaluate`` opened once: a :class:`~hpe_cli.io.label_source.LabelSource`.

    ``system`` is the ``--{role}-system`` option (the file's own system wins; a dataset format's labels are
    converted to it), ``use`` the ``--columns`` choice (``"auto"``: the system's own value columns, then
    angles, then ``r00..r22``).
    """
    table = open_table(path, batch_size, with_lines=True)
    resolved = resolve_system(table, system, default=None, option_name=f"--{role}-system", option_is_output=True)
    columns = side_columns(table)
    if use == AUTO:
        return LabelSource(table, resolved, label_mode(columns, table.path, resolved.system))
    native = resolved.system.storage_kind == use and all(c in columns for c in resolved.system.value_columns)
    need = ANGLE_COLS if use == "angles" else MATRIX_COLS
    missing = [c for c in need if c not in columns]
    if missing and not native:
        raise HpeError(f"{table.path}: missing column(s) {', '.join(missing)} for --columns {use}")
    return LabelSource(table, resolved, use)


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
        #: key columns whose hash each chunk carries (set while streaming unsorted keys: hashed on the label threads)
        self.hash_keys: list | None = None
        self.image_dir = src.path if self.dataset_stem else None
        #: how a row is named in messages: Parquet "row N" (1-based), text "line N" (header = line 1)
        self.unit = "row" if src.kind == "parquet" else "line"

    def chunks(self):
        """Yield one :class:`Chunk` per batch of the table, in file order.

        The batches are decoded here, one after the other; their labels (matrices from the angles, checks) are
        computed on ``threads`` threads (:data:`LABEL_THREADS` by default), at most that many batches ahead.
        """

        def batches():
            for batch, bad_rows in self.src.batches_with_rejects():
                self.unreadable += [(r.line, r.reason) for r in bad_rows]
                yield batch

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
        X, ok, rs, raw, dist = _batch_labels(batch, self.system, self.mode, self.radians, self.orthonormalize)
        n = batch.num_rows
        X = self.system.soa_to_canonical(X)
        keys = batch.select(self.keep) if self.keep else None
        by = keys.column(self.by).to_numpy(zero_copy_only=False) if self.by else None
        kh = keys_hash(keys, self.hash_keys) if self.hash_keys and keys is not None else None
        return Chunk(soa.columns(X, n), ok, rs, raw, dist, keys, by, lines, kh)


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


class JoinUsageError(HpeError):
    """A join that cannot be made as asked (the CLI turns it into a usage error, exit 2)."""

    exit_code = 2


def choose_keys(keys, pred_cols, gt_cols, pred_path, gt_path, join_mode="key"):
    if join_mode == "order":
        return []
    if keys:
        for side_cols, p in ((gt_cols, gt_path), (pred_cols, pred_path)):
            bad = [k for k in keys if k not in side_cols]
            if bad:
                raise HpeError(
                    f"{p}: --key column(s) {', '.join(bad)} not in the table; found: {', '.join(side_cols[:20])}"
                )
        return list(keys)
    for k in DEFAULT_KEYS:
        if k in pred_cols and k in gt_cols:
            return [k]
    raise JoinUsageError(
        f"{pred_path}: no key column shared with {gt_path} (looked for {', '.join(DEFAULT_KEYS)}; "
        f"prediction columns: {', '.join(pred_cols[:12])}); give --key COL[,COL...], or "
        "--join order to pair rows by position (only with equal row counts)"
    )


def file_stems(arr):

    return pc.replace_substring_regex(pc.cast(arr, pa.string()), r"^.*[\\/]|\.[^.\\/]*$", "")


def _encode(a, b):

    enc = pa.concat_arrays([a, b]).dictionary_encode(null_encoding="encode")
    return arrow_to_numpy(enc.indices).astype(np.int64), len(enc.dictionary)


def _key_codes(gt_keys, pred_keys, keys, stems=None):
    """One int64 code per row of each side (equal codes iff all key columns are equal) and the notes.

    Text keys that name files are compared as written; when that matches fewer
    rows than comparing their file stems (``image00050.jpg``, ``AFLW/image00050.mat``
    and ``image00050`` are one image), the stems are used and a note says so. ``stems`` (a set of key
    columns), when given, makes that choice instead (the partitioned join decides it over the whole files).
    """

    n_g = gt_keys.num_rows
    code, notes = None, []
    for k in keys:
        a = gt_keys.column(k).combine_chunks()
        b = pred_keys.column(k).combine_chunks()
        if a.type != b.type:  # a key read as numbers on one side and text on the other: compare as text
            a, b = pc.cast(a, pa.string()), pc.cast(b, pa.string())
        c, m = _encode(a, b)
        if stems is not None:
            if k in stems:
                c, m = _encode(file_stems(a), file_stems(b))
                notes.append(f"key {k!r} joined on file stems (the two files spell the names differently)")
        elif pa.types.is_string(a.type) or pa.types.is_large_string(a.type):
            exact = np.isin(c[:n_g], c[n_g:]).sum()
            if exact < min(n_g, len(c) - n_g):
                cs, ms = _encode(file_stems(a), file_stems(b))
                if np.isin(cs[:n_g], cs[n_g:]).sum() > exact:
                    c, m = cs, ms
                    notes.append(f"key {k!r} joined on file stems (the two files spell the names differently)")
        if code is None:
            code = c
        else:
            code = code * m + c
            code = np.unique(code, return_inverse=True)[1].astype(np.int64).reshape(-1)
    return code[:n_g], code[n_g:], notes


def where(side, row):
    unit = side.unit
    if side.image_dir is not None:
        return f"{side.path}"
    return f"{side.path}: {unit} {int(side.lines[row])}"


def _check_unique(codes, side, keys):
    counts = np.bincount(codes) if len(codes) else np.zeros(0, dtype=np.int64)
    dup = counts[codes] > 1
    if dup.any():
        first = int(np.flatnonzero(dup)[0])
        again = int(np.flatnonzero(codes == codes[first])[1])
        what = ", ".join(f"{k}={side.keys.column(k)[first].as_py()!r}" for k in keys)
        unit = side.unit
        raise HpeError(
            f"{where(side, first)}: duplicate key {what} (again at {unit} {int(side.lines[again])}); "
            f"choose --key columns that identify one row, e.g. --key {','.join(keys)},person_id"
        )


def join(pred: Side, gt: Side, keys, join_mode="key", stems=None, codes=None):
    """``(gt_idx, pred_idx, unmatched prediction rows, notes)``; pred_idx is -1 where a GT row has no prediction.

    ``stems``: see :func:`_key_codes`; ``codes``: the ``(gt, pred)`` key codes when the caller has them
    (the partitioned join, from verified key hashes)."""
    if join_mode == "order":
        if pred.n != gt.n:
            raise JoinUsageError(
                f"{pred.path}: --join order pairs rows by position and needs equal row counts; "
                f"got {pred.n} predictions and {gt.n} ground-truth rows in {gt.path}"
            )
        idx = np.arange(gt.n)
        return idx, idx.copy(), np.zeros(0, dtype=np.int64), ["rows paired by position (--join order)"]
    if codes is not None:
        cg, cp = codes
        notes = [
            f"key {k!r} joined on file stems (the two files spell the names differently)"
            for k in keys
            if k in (stems or ())
        ]
    else:
        cg, cp, notes = _key_codes(gt.keys, pred.keys, keys, stems)
    _check_unique(cg, gt, keys)
    _check_unique(cp, pred, keys)
    m = int(max(cg.max(initial=-1), cp.max(initial=-1))) + 1
    pred_pos = np.full(m, -1, dtype=np.int64)
    pred_pos[cp] = np.arange(len(cp))
    gt_has = np.zeros(m, dtype=bool)
    gt_has[cg] = True
    return np.arange(len(cg)), pred_pos[cg], np.flatnonzero(~gt_has[cp]), notes


def row_reasons(side: Side, idx):
    if side.reasons is None:
        return np.full(len(idx), "", dtype=object)
    return side.reasons[idx]


def _gather(side, idx):
    """Canonical nested matrix of the rows ``idx`` (no copy when every row is used in its own order)."""
    if len(idx) == side.n and (idx[0] == 0 if len(idx) else True) and np.all(np.diff(idx) == 1):
        return [[side.canonical[3 * i + j] for j in range(3)] for i in range(3)]
    return [[side.canonical[3 * i + j][idx] for j in range(3)] for i in range(3)]
