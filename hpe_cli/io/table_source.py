"""The streamed table every reader returns (:class:`TableSource`), its rejects and row numbering."""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import HpeError
from .layout import ANGLE2_COLS, ANGLE_COLS, BBOX_COLS, MATRIX_COLS

#: rows per batch: large enough to amortise per-batch costs, small enough that the few batches in flight
#: (read, converted on two threads, written) keep a 10M-row job under 300 MB
DEFAULT_BATCH = 65_536
#: bytes of CSV parsed at a time (the reader's memory is a few times this)
CSV_BLOCK = 1 << 24
#: the column holding each row's line number when ``open_table(..., with_lines=True)``
LINE_COL = "__line__"
#: raw text kept for a rejected row (characters)
RAW_MAX = 200


def float_columns() -> frozenset:
    """Names of the standard columns read as floats (angles, matrix, box, quaternion, ...)."""

    names = set(ANGLE_COLS) | set(ANGLE2_COLS) | set(MATRIX_COLS) | set(BBOX_COLS)
    names |= {"roundtrip_err", "lock_dist", "rx", "ry", "rz", "qw", "qx", "qy", "qz"}
    return frozenset(names)


def is_float_column(name: str, floats=None) -> bool:
    """Columns always read as float64 from CSV: label, box and landmark (``lm{i}_x/y/z``) columns."""

    return name in (floats if floats is not None else float_columns()) or re.fullmatch(r"lm\d+_[xyz]", name) is not None


@dataclass
class Reject:
    """A row the reader could not parse: 1-based file line, reason, raw text (truncated)."""

    line: int
    reason: str
    raw: str


@dataclass
class TableSource:
    """A table read lazily in record batches (:meth:`where` names a row in messages).

    ``batches()`` yields pyarrow RecordBatches and raises an :class:`HpeError`
    naming the file, line and reason at the first unreadable row;
    ``batches_with_rejects()`` yields ``(batch, rejects)`` pairs instead, where
    ``rejects`` is a list of :class:`Reject` for rows set aside since the
    previous batch, so a command can put them in its rejects file.
    """

    path: Path
    schema: object
    num_rows: int | None
    _batches: Callable[[], Iterator]
    with_lines: bool = False
    kind: str = "table"
    _pending: list = field(default_factory=list)
    #: rotation system the reader's labels are in ("300w_lp" for .mat, "biwi", "dad3dheads", a Parquet
    #: file's hpe:system metadata), or None when the file does not say
    system: str | None = None
    #: True when a dataset reader (.mat, 300W-LP, BIWI, DAD-3DHeads) produced the labels: their system is
    #: fixed by the dataset, whatever a command's --system says
    dataset: bool = False
    #: how a row is named in messages and rejects files: "line" (text: 1-based file line, header = line 1),
    #: "row" (Parquet, JSON, dataset tables: 1-based row), "file" (one record per file: ``row_files``)
    unit: str = "line"
    #: with ``unit == "file"``: the file (relative to ``path`` when it is a folder) that holds each row
    row_files: list | None = None

    @property
    def columns(self) -> list:
        return [n for n in self.schema.names if n != LINE_COL]

    def where(self, n) -> str:
        """The name of row ``n`` (its ``__line__`` value): ``FILE: line N``, ``FILE: row N`` or ``FILE``.

        One rule for every message and rejects file: text files are numbered by
        their 1-based line (header = line 1), Parquet/JSON/dataset tables by
        their 1-based row, and a row read from a one-record file (a ``.mat``
        of a folder, a BIWI pose file) by that file.
        """
        n = int(n)
        if self.unit == "file":
            if self.row_files is not None and 1 <= n <= len(self.row_files):
                name = self.row_files[n - 1]
                return str(self.path / name) if self.path.is_dir() else f"{self.path}: {name}"
            return str(self.path)
        return f"{self.path}: {self.unit} {n}"

    def batches_with_rejects(self) -> Iterator:
        import pyarrow as pa  # lazy: start-up

        try:
            for item in self._batches():
                # readers yield (batch, rejects) pairs; simple dataset readers may yield bare batches
                batch, rejects = item if isinstance(item, tuple) else (item, [])
                if not self.with_lines and LINE_COL in batch.schema.names:
                    batch = batch.drop_columns([LINE_COL])
                yield batch, rejects
        except (pa.ArrowInvalid, OSError, ValueError) as exc:
            raise HpeError(f"{self.path}: cannot read: {one_line(exc)}") from None

    def batches(self) -> Iterator:
        """Yield pyarrow RecordBatches; the first unreadable row becomes an HpeError."""
        for batch, rejects in self.batches_with_rejects():
            if rejects:
                r = rejects[0]
                raise HpeError(f"{self.where(r.line)}: {r.reason}")
            yield batch


def one_line(exc) -> str:
    """An exception's message on one line (at most 300 characters), for error messages."""
    return " ".join(str(exc).split())[:300]


def table_schema(schema, with_lines):
    """A table's schema, with the line-number column appended when ``with_lines``."""
    import pyarrow as pa  # lazy: start-up

    return schema.append(pa.field(LINE_COL, pa.int64())) if with_lines else schema


def with_line_numbers(batch, first_line: int):
    """``batch`` with the line-number column appended, numbered from ``first_line``."""
    import pyarrow as pa  # lazy: start-up

    n = batch.num_rows  # from_buffers: zero copy, and pa.array's import of pandas (0.4 s) is not needed here
    lines = pa.Array.from_buffers(
        pa.int64(), n, [None, pa.py_buffer(np.arange(first_line, first_line + n, dtype=np.int64))]
    )
    return batch.append_column(LINE_COL, lines)


_PLAIN = {"double": np.float64, "float": np.float32, "int64": np.int64, "int32": np.int32}


def plain_numpy(arr) -> np.ndarray:
    """A numeric Arrow array as numpy: a zero-copy view of its buffer when it has no nulls and a plain type
    (``to_numpy`` would import pandas, 0.4 s, on its first call), else ``to_numpy``."""
    dt = _PLAIN.get(str(arr.type))
    if dt is not None and arr.null_count == 0 and hasattr(arr, "buffers"):
        return np.frombuffer(arr.buffers()[1], dtype=dt, count=len(arr), offset=arr.offset * np.dtype(dt).itemsize)
    return arr.to_numpy(zero_copy_only=False)


def check_duplicates(path, names, where="line 1: "):
    """Raise HpeError if a column name repeats or is the reserved line-number column."""

    dup = [n for n, c in Counter(names).items() if c > 1]
    if dup:
        raise HpeError(
            f"{path}: {where}duplicate column name(s) {', '.join(map(repr, dup))}: expected each column once"
        )
    if LINE_COL in names:
        raise HpeError(f"{path}: {where}column name {LINE_COL!r} is reserved")


#: suffixes of tables whose rows are numbered as rows (not text lines)
_ROW_SUFFIXES = (".parquet", ".pq", ".json", ".mat", ".zip", ".tgz", ".gz", ".tar")


def row_name(path, n) -> str:
    """``TableSource.where`` from a path and a row's ``__line__`` value alone (for code that kept only those).

    A number names a text file's line or another table's row; a name (a
    ``.mat`` file of a folder) names that file.
    """
    p = Path(str(path))
    try:
        k = int(n)
        if float(n) != k:
            raise ValueError
    except (TypeError, ValueError):
        return str(p / str(n)) if p.is_dir() else f"{p}: {n}"
    unit = "row" if (p.is_dir() or p.suffix.lower() in _ROW_SUFFIXES) else "line"
    return f"{p}: {unit} {k}"
