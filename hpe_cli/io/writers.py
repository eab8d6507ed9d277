"""Atomic table writers (Parquet or CSV by extension), streaming by batches.

Output goes to a temporary file next to the target and is renamed into place
only when everything succeeded, so a failure never leaves a half-written file.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import HpeError

TABLE_SUFFIXES = (".parquet", ".pq", ".csv")


def table_format(path) -> str:
    s = Path(path).suffix.lower()
    if s in (".parquet", ".pq"):
        return "parquet"
    if s == ".csv":
        return "csv"
    raise HpeError(f"{path}: expected an output ending in .parquet or .csv, got {s or 'no extension'!r}")


def check_output(path, overwrite: bool) -> Path:
    """Refuse to clobber an existing file without ``overwrite``, or to write where a folder is."""
    path = Path(path)
    if path.is_dir():
        raise HpeError(f"{path}: is a folder, expected a file name")
    if path.exists() and not overwrite:
        raise HpeError(f"{path}: already exists (use --overwrite to replace it)")
    if path.parent.exists() and not path.parent.is_dir():
        raise HpeError(f"{path}: {path.parent} is not a folder")
    return path


def system_metadata(system) -> dict:
    """Parquet key-value metadata describing the labels' rotation system."""
    return {"hpe:system": system.name, "hpe:system_definition": system.to_json()}


class AtomicFile:
    """Context manager giving a temporary path whose content becomes ``path``.

    Inside a run (an active :class:`~hpe_cli.io.transaction.OutputTransaction`)
    the file is staged and committed with the run's other outputs; alone, it is
    committed when the block ends. On an error the temporary file is removed,
    and an OS error while writing it names ``path`` and the reason.
    """

    def __init__(self, path, overwrite: bool = False):
        self.path = check_output(path, overwrite)
        self.overwrite = overwrite
        self.tmp = None

    def __enter__(self) -> Path:
        from .transaction import OutputTransaction, current  # lazy: start-up

        txn = current()
        self._own = txn is None
        self._txn = OutputTransaction() if self._own else txn
        self.tmp = self._txn.stage_file(self.path, self.overwrite)
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            if self._own:
                self._txn.abort()
            else:
                self._txn.discard(self.tmp)
            if isinstance(exc, OSError) and _mentions(exc, self.tmp):
                raise HpeError(f"{self.path}: cannot write: {_reason(exc)}") from None
            return False
        if self._own:
            self._txn.commit()
        return False


def _mentions(exc, tmp) -> bool:
    name = Path(tmp).name
    return name in str(getattr(exc, "filename", "") or "") or name in str(exc) or getattr(exc, "filename", None) is None


def _reason(exc) -> str:
    from .transaction import os_reason  # lazy: start-up

    return os_reason(exc)


class TableWriter:
    """Write pyarrow record batches to Parquet or CSV atomically.

    The schema is taken from the first batch; later batches are cast to it.
    """

    def __init__(self, path, overwrite: bool = False, metadata: dict | None = None):
        self.fmt = table_format(path)
        self._atomic = AtomicFile(path, overwrite)
        self.metadata = {k: (v if isinstance(v, str) else json.dumps(v)) for k, v in (metadata or {}).items()}
        self._writer = None
        self.rows = 0

    @property
    def path(self) -> Path:
        return self._atomic.path

    def __enter__(self):
        self._tmp = self._atomic.__enter__()
        return self

    def write(self, batch) -> None:
        import pyarrow as pa  # lazy: start-up

        if isinstance(batch, dict):
            batch = pa.RecordBatch.from_pydict(batch)
        elif not isinstance(batch, (pa.RecordBatch, pa.Table)):  # a pandas DataFrame
            batch = pa.Table.from_pandas(batch, preserve_index=False)
        if self._writer is None:
            schema = batch.schema
            if self.metadata and self.fmt == "parquet":
                schema = schema.with_metadata({**(schema.metadata or {}), **self.metadata})
            self._schema = schema
            try:
                self._writer = self._open(schema)
            except OSError as exc:
                raise HpeError(f"{self.path}: cannot write: {_reason(exc)}") from None
        if batch.schema != self._schema:
            batch = (
                batch.cast(self._schema)
                if isinstance(batch, pa.Table)
                else pa.Table.from_batches([batch]).cast(self._schema)
            )
        try:
            self._writer.write(batch)
        except OSError as exc:
            raise HpeError(f"{self.path}: cannot write: {_reason(exc)}") from None
        self.rows += batch.num_rows

    def _open(self, schema):
        if self.fmt == "parquet":
            import pyarrow as pa  # lazy: start-up
            import pyarrow.parquet as pq  # lazy: start-up

            # continuous floats neither repeat (dictionary pages) nor compress (snappy finds
            # nothing in float64 mantissas): both cost write time for no gain
            floats = {f.name for f in schema if pa.types.is_floating(f.type)}
            return pq.ParquetWriter(
                self._where(),
                schema,
                use_dictionary=[n for n in schema.names if n not in floats],
                compression={n: ("none" if n in floats else "snappy") for n in schema.names},
            )
        import pyarrow.csv as pcsv  # lazy: start-up

        return pcsv.CSVWriter(self._where(), schema)

    def _where(self):
        """The temporary path, or an open file when the path is not valid UTF-8 (Arrow needs UTF-8 names)."""
        try:
            str(self._tmp).encode("utf-8")
            return str(self._tmp)
        except UnicodeEncodeError:
            self._file = open(self._tmp, "wb")
            return self._file

    def __exit__(self, exc_type, exc, tb):
        try:
            if self._writer is not None:
                try:
                    self._writer.close()
                    if getattr(self, "_file", None) is not None:
                        self._file.close()
                except OSError as e:
                    raise HpeError(f"{self.path}: cannot write: {_reason(e)}") from None
            elif exc_type is None:
                raise HpeError(f"{self.path}: nothing to write (no rows and no schema)")
        except BaseException as e:
            self._atomic.__exit__(type(e), e, None)
            raise
        return self._atomic.__exit__(exc_type, exc, tb)


class StreamWriter:
    """Base of the streaming text writers (:class:`~hpe_cli.io.coco.CocoWriter`,
    :class:`~hpe_cli.io.whenet_txt.WhenetWriter`): the output is staged like any
    other (:class:`AtomicFile`) and its bytes go out through a
    :class:`~hpe_cli.io.background.BackgroundFile` (a writer thread), so one
    batch is written while the next is formatted.

    A subclass formats rows and hands them to :meth:`append_text` (or
    :meth:`append_file`, for text made elsewhere); :attr:`separator` goes
    between two non-empty pieces, :meth:`head` opens the file and
    :meth:`tail` closes it.
    """

    #: bytes between two non-empty pieces of rows
    separator = b""

    def __init__(self, path, overwrite: bool = False):
        self._atomic = AtomicFile(path, overwrite)  # refuse an existing file before doing any work
        self.path = Path(path)
        self.rows = 0
        self._out = None

    def head(self) -> bytes:
        """Bytes before the first row."""
        return b""

    def tail(self) -> bytes:
        """Bytes after the last row (asked for once every row is in)."""
        return b""

    def __enter__(self):
        from .background import BackgroundFile  # lazy: start-up

        self._tmp = self._atomic.__enter__()
        try:
            self._out = BackgroundFile(open(self._tmp, "wb"))
            self._out.write(self.head())
        except BaseException as e:
            if self._out is not None:
                self._out.abort()
            self._atomic.__exit__(type(e), e, None)
            raise
        return self

    def append_text(self, text, rows: int) -> None:
        """Append ``rows`` rows already formatted as ``text`` (bytes-like)."""
        self._append(rows, self._out.write, text)

    def append_file(self, path, rows: int) -> None:
        """Append ``rows`` rows whose formatted text is the content of the file ``path`` (copied by the kernel
        where it can; the file may be removed as soon as this returns)."""
        self._append(rows, self._out.copy_from, path)

    def _append(self, rows: int, put, piece) -> None:
        if rows:
            if self.rows and self.separator:
                self._out.write(self.separator)
            put(piece)
        self.rows += rows

    def __exit__(self, exc_type, exc, tb):
        try:
            if exc_type is None:
                self._out.write(self.tail())
                self._out.close()
            else:
                self._out.abort()
        except BaseException as e:
            self._out.abort()
            self._atomic.__exit__(type(e), e, None)
            raise
        return self._atomic.__exit__(exc_type, exc, tb)


def write_table(table, path, overwrite: bool = False, metadata: dict | None = None) -> Path:
    """Write one table (pyarrow Table, dict of arrays or pandas DataFrame) atomically."""
    with TableWriter(path, overwrite, metadata) as w:
        w.write(table)
    return w.path


def write_json(obj, path, overwrite: bool = False) -> Path:
    """Write JSON atomically."""
    with AtomicFile(path, overwrite) as tmp:
        tmp.write_text(json_text(obj), encoding="utf-8")
    return Path(path)


def json_text(obj) -> str:
    """The JSON text :func:`write_json` writes (indented; numpy scalars and arrays as numbers and lists)."""
    return json.dumps(obj, indent=2, default=_json_default)


def check_report_outputs(report, output, overwrite: bool) -> None:
    """Before any work: a ``--json`` report (``-`` = stdout) and an ``-o`` table may be written (name, suffix)."""
    for p in (report if report != "-" else None, output):
        if p:
            check_output(p, overwrite)
    if output:
        table_format(output)


def _json_default(o):

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
