"""Streaming table readers: Parquet, CSV, or a folder of 300W-LP/AFLW2000 ``.mat`` files.

Memory does not depend on the number of rows: Parquet is read one record
batch at a time without pre-buffering, CSV in bounded blocks of bytes.

Row numbers ("line N")
----------------------
Every row has a 1-based *line number*: for CSV it is the file line where the
record starts (the header is line 1, blank lines count, a record with quoted
newlines counts from its first line); for Parquet and dataset folders it is
the line the row would have in a CSV with a header (first row = line 2).

Bad CSV rows
------------
A CSV row with the wrong number of fields, an unclosed quote, bytes that are
not UTF-8, or a value that does not fit its column's type is a *reject*: the
reader sets it aside with its line, the reason and its raw text, and goes on.
Label columns (angles, matrix entries, ... see :data:`FLOAT_COLUMNS`) are
always read as float64, so "non-numeric value in pitch" means the same on line
3 as on line 30,000,000; other columns take the type pyarrow infers from the
first block (a later value that does not fit it is a reject saying so).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from ..errors import HpeError

#: rows per batch: large enough to amortise per-batch costs, small enough that the few batches in flight
#: (read, converted on two threads, written) keep a 10M-row job under 300 MB
DEFAULT_BATCH = 65_536
#: bytes of CSV parsed at a time (the reader's memory is a few times this)
CSV_BLOCK = 1 << 24
#: the column holding each row's line number when ``open_table(..., with_lines=True)``
LINE_COL = "__line__"
#: raw text kept for a rejected row (characters)
RAW_MAX = 200


def _float_columns() -> frozenset:
    from .layout import ANGLE2_COLS, ANGLE_COLS, BBOX_COLS, MATRIX_COLS

    names = set(ANGLE_COLS) | set(ANGLE2_COLS) | set(MATRIX_COLS) | set(BBOX_COLS)
    names |= {"roundtrip_err", "lock_dist", "rx", "ry", "rz", "qw", "qx", "qy", "qz"}
    return frozenset(names)


def is_float_column(name: str, floats=None) -> bool:
    """Columns always read as float64 from CSV: label, box and landmark (``lm{i}_x/y/z``) columns."""
    import re

    return name in (floats if floats is not None else _float_columns()) or \
        re.fullmatch(r"lm\d+_[xyz]", name) is not None


@dataclass
class Reject:
    """A row the reader could not parse: 1-based file line, reason, raw text (truncated)."""

    line: int
    reason: str
    raw: str


@dataclass
class TableSource:
    """A table read lazily in record batches.

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

    @property
    def columns(self) -> list:
        return [n for n in self.schema.names if n != LINE_COL]

    def batches_with_rejects(self) -> Iterator:
        import pyarrow as pa

        try:
            for item in self._batches():
                # readers yield (batch, rejects) pairs; simple dataset readers may yield bare batches
                batch, rejects = item if isinstance(item, tuple) else (item, [])
                if not self.with_lines and LINE_COL in batch.schema.names:
                    batch = batch.drop_columns([LINE_COL])
                yield batch, rejects
        except (pa.ArrowInvalid, OSError, ValueError) as exc:
            raise HpeError(f"{self.path}: cannot read: {_one_line(exc)}") from None

    def batches(self) -> Iterator:
        """Yield pyarrow RecordBatches; the first unreadable row becomes an HpeError."""
        for batch, rejects in self.batches_with_rejects():
            if rejects:
                r = rejects[0]
                raise HpeError(f"{self.path}: line {r.line}: {r.reason}")
            yield batch


def _one_line(exc) -> str:
    return " ".join(str(exc).split())[:300]


def sniff(path: Path) -> str:
    """The kind of a file from its first bytes: parquet, pickle, zip, gzip, json, mat, or text."""
    with open(path, "rb") as f:
        head = f.read(512)
    if head[:4] == b"PAR1":
        return "parquet"
    if head[:1] == b"\x80" and len(head) > 1 and 2 <= head[1] <= 5:
        return "pickle"
    if head[:2] == b"PK":
        return "zip"
    if head[:2] == b"\x1f\x8b":
        return "gzip"
    if head[:6] == b"MATLAB":
        return "mat"
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "utf16"
    stripped = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if stripped[:1] in (b"{", b"["):
        return "json"
    return "text"


#: inputs that the command-wide --delimiter/--no-header/--names/--input-format options never apply to
_NOT_TEXT = (".parquet", ".pq", ".mat", ".zip", ".tgz", ".gz", ".tar", ".npz", ".pkl", ".pickle")


def open_table(path, batch_size: int = DEFAULT_BATCH, columns=None, delimiter=None, header: bool = True,
               input_format=None, names=None, with_lines: bool = False, block_size: int | None = None) -> TableSource:
    """Open a label table for streaming.

    ``columns`` renames columns (``"pitch=Pitch,yaw=Yaw"`` or ``{"pitch": "Pitch"}``);
    ``delimiter``/``header``/``names`` read delimited text of any suffix;
    ``input_format`` names a label list (see :mod:`hpe_cli.io.columns`); COCO
    ``.json`` and WHENet ``annotation.txt`` are recognised without it. Without
    these arguments, the running command's ``--columns-map``/``--delimiter``/...
    options apply (:func:`hpe_cli.cli.table_options.column_options`).
    """
    from .columns import active_table_options, apply_columns_map, open_formatted

    if columns is None and delimiter is None and header and input_format is None and names is None:
        active = active_table_options()
        if active:
            columns, delimiter, header = active["columns"], active["delimiter"], active["header"]
            input_format, names = active["input_format"], active["names"]
            p = Path(path)
            if p.is_dir() or p.suffix.lower() in _NOT_TEXT:
                # a command with several inputs (evaluate PRED GT): text options apply to its text inputs
                delimiter, header, input_format, names = None, True, None, None
            if columns:
                from .columns import LenientMap

                columns = LenientMap(columns)
    src = open_formatted(path, batch_size, input_format=input_format, delimiter=delimiter, header=header,
                         names=names, with_lines=with_lines)
    if src is None:
        src = _open_core(path, batch_size, with_lines=with_lines, block_size=block_size or CSV_BLOCK)
    return apply_columns_map(src, columns)


def _open_core(path, batch_size: int = DEFAULT_BATCH, *, with_lines: bool = False,
               block_size: int = CSV_BLOCK) -> TableSource:
    """Open a label table for streaming.

    ``path`` may be Parquet, CSV (recognised by content, not by extension), a
    folder of ``.mat`` files (read from ``Pose_Para``, see
    :func:`hpe_cli.datasets.mat.read_mat_dir`), or BIWI pose files (a folder,
    one file, or ``db_annotations.tgz``; angles in the ``biwi`` system).
    With ``with_lines=True`` every batch carries an int64 ``__line__`` column
    (see the module docstring).
    """
    import pyarrow as pa

    path = Path(path)
    if not path.exists():
        raise HpeError(f"{path}: no such file or folder")
    dataset = _read_dataset(path)
    if dataset is not None and hasattr(dataset, "iter_batches"):  # a dataset reader that streams

        def gen_stream():
            line = 2
            for b in dataset.iter_batches():
                yield _with_line(b, line), []
                line += b.num_rows
        return TableSource(path, _schema(dataset.schema, with_lines), dataset.num_rows, gen_stream, with_lines,
                           "dataset", system=dataset.system, dataset=True)
    if dataset is not None:
        system = dataset.attrs.get("system")
        table = pa.Table.from_pandas(dataset, preserve_index=False)

        def gen():
            for start in range(0, max(table.num_rows, 1), batch_size):
                b = table.slice(start, batch_size).combine_chunks().to_batches()
                b = b[0] if b else pa.RecordBatch.from_pylist([], schema=table.schema)
                yield _with_line(b, start + 2), []
        return TableSource(path, _schema(table.schema, with_lines), table.num_rows, gen, with_lines, "dataset",
                           system=system, dataset=system is not None)
    if path.is_dir():
        raise HpeError(f"{path}: expected a table file, got a folder")
    if path.stat().st_size == 0:
        raise HpeError(f"{path}: empty file")
    kind = sniff(path)
    try:
        if kind == "parquet":
            return _open_parquet(path, batch_size, with_lines)
        if kind == "text":
            return _open_csv(path, batch_size, with_lines, block_size)
    except (pa.ArrowInvalid, OSError) as exc:
        raise HpeError(f"{path}: cannot read: {_one_line(exc)}") from None
    what = {"pickle": "a Python pickle (hpe never loads pickles as tables; AGORA dataframes go to "
                      "'hpe relabel-agora')",
            "zip": "a zip archive", "gzip": "a gzip file (decompress it first)", "json": "JSON",
            "mat": "a MATLAB .mat file (give the .mat file or its folder with a .mat name)",
            "utf16": "UTF-16 text (save it as UTF-8)"}[kind]
    raise HpeError(f"{path}: expected a Parquet or CSV table, got {what}")


def _schema(schema, with_lines):
    import pyarrow as pa

    return schema.append(pa.field(LINE_COL, pa.int64())) if with_lines else schema


def _with_line(batch, first_line: int):
    import pyarrow as pa

    lines = pa.array(np.arange(first_line, first_line + batch.num_rows, dtype=np.int64))
    return batch.append_column(LINE_COL, lines)


def _check_duplicates(path, names):
    from collections import Counter

    dup = [n for n, c in Counter(names).items() if c > 1]
    if dup:
        raise HpeError(f"{path}: line 1: duplicate column name(s) {', '.join(map(repr, dup))}: "
                       f"expected each column once")
    if LINE_COL in names:
        raise HpeError(f"{path}: line 1: column name {LINE_COL!r} is reserved")


def _open_parquet(path, batch_size, with_lines):
    import pyarrow.parquet as pq

    pf = pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20)
    schema = pf.schema_arrow
    _check_duplicates(path, schema.names)

    def gen():
        # one row group at a time, one batch at a time: nothing read is kept
        line = 2
        f = pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20)
        for rg in range(f.num_row_groups):
            for b in f.iter_batches(batch_size=batch_size, row_groups=[rg], use_threads=True):
                yield (_with_line(b, line) if with_lines else b), []
                line += b.num_rows
    meta = schema.metadata or {}
    system = meta[b"hpe:system"].decode("utf-8", "replace") if b"hpe:system" in meta else None
    return TableSource(path, _schema(schema, with_lines), pf.metadata.num_rows, gen, with_lines, "parquet",
                       system=system)


# ----------------------------------------------------------------------------------------------------- CSV
def _open_csv(path, batch_size, with_lines, block_size):
    import pyarrow as pa

    reader = _CsvBlocks(path, block_size)
    header, header_lines = reader.header()
    names = _parse_header(path, header)
    _check_duplicates(path, names)
    schema = reader.infer_schema(names, header_lines)

    def gen():
        blocks = _CsvBlocks(path, block_size)
        _, first_line = blocks.header()
        for table, rejects in blocks.tables(schema, first_line):
            if table.num_rows == 0:
                if rejects:
                    yield pa.RecordBatch.from_pylist([], schema=table.schema), rejects
                continue
            for k, b in enumerate(table.to_batches(max_chunksize=batch_size)):
                yield b, (rejects if k == 0 else [])
    return TableSource(path, _schema(schema, with_lines), None, gen, with_lines, "csv")


def _parse_header(path, header: bytes) -> list:
    import csv

    try:
        text = header.decode("utf-8")
    except UnicodeDecodeError:
        raise HpeError(f"{path}: line 1: the header is not UTF-8 text: expected a UTF-8 CSV") from None
    rows = list(csv.reader([text.rstrip("\r\n")]))
    if not rows or not rows[0] or rows[0] == [""]:
        raise HpeError(f"{path}: line 1: empty header: expected column names")
    return rows[0]


_NULLS = None


def _null_values():
    global _NULLS
    if _NULLS is None:
        import pyarrow.csv as pcsv

        _NULLS = list(pcsv.ConvertOptions().null_values)
    return _NULLS


class _CsvBlocks:
    """Split a CSV file into blocks of whole records, with their first line numbers."""

    def __init__(self, path, block_size):
        self.path = path
        self.block_size = block_size
        self._f = None
        self._rest = b""
        self._line = 1
        self.ncols = None

    def header(self):
        """Raw header record and the line number of the first data line."""
        self._f = open(self.path, "rb")
        first = self._f.read(min(self.block_size, 1 << 20))
        if first.startswith(b"\xef\xbb\xbf"):
            first = first[3:]
        while b"\n" not in first:
            more = self._f.read(1 << 20)
            if not more:
                break
            first += more
            if len(first) > (16 << 20):
                raise HpeError(f"{self.path}: line 1: header longer than 16 MB: expected a CSV header line")
        cut = first.find(b"\n")
        if cut < 0:
            cut = len(first) - 1
        header, self._rest = first[:cut + 1], first[cut + 1:]
        self._line = 2
        return header, 2

    def raw_blocks(self):
        """Yield ``(bytes, first_line)``: whole records (cut at a newline outside quotes)."""
        f, size = self._f, self.block_size
        eof = False
        while True:
            chunk = f.read(size)
            eof = len(chunk) < size
            data = self._rest + chunk
            self._rest = b""
            if not data:
                break
            if eof:
                block = data
            else:
                cut = _last_record_end(data)
                if cut < 0 and len(data) > 2 * size:
                    cut = data.rfind(b"\n")  # an unclosed quote: cut at a line; the block's parser rejects it
                if cut < 0:
                    self._rest = data
                    continue
                block, self._rest = data[:cut + 1], data[cut + 1:]
            nnl = block.count(b"\n")
            yield block, self._line, nnl
            self._line += nnl
            if eof:
                break
        f.close()

    def infer_schema(self, names, first_line):
        """Column types from the first block: float columns forced to float64, null columns to string."""
        import pyarrow as pa
        import pyarrow.csv as pcsv

        self.ncols = len(names)
        floats = _float_columns()
        for block, line, _ in self.raw_blocks():
            types = {n: pa.string() for n in names if is_float_column(n, floats)}
            t = None
            for attempt in range(2):
                if attempt:
                    good, _, _ = _split_records(block, line, len(names))
                    block = b"".join(good) if isinstance(good, list) else good
                try:
                    t = pcsv.read_csv(pa.py_buffer(block), read_options=pcsv.ReadOptions(column_names=names),
                                      parse_options=pcsv.ParseOptions(newlines_in_values=b'"' in block),
                                      convert_options=pcsv.ConvertOptions(column_types=types))
                    break
                except pa.ArrowInvalid:
                    t = None
            fields = []
            for n in names:
                typ = t.schema.field(n).type if t is not None else pa.string()
                if is_float_column(n, floats):
                    typ = pa.float64()
                elif pa.types.is_null(typ) or pa.types.is_binary(typ):
                    typ = pa.string()
                fields.append(pa.field(n, typ))
            break
        else:
            fields = [pa.field(n, pa.float64() if is_float_column(n, floats) else pa.string()) for n in names]
        self._f.close()
        return pa.schema(fields)

    def tables(self, schema, first_line):
        for block, line, nnl in self.raw_blocks():
            yield _parse_block(self.path, block, line, schema, nnl)


def _last_record_end(data: bytes, max_lines: int = 100_000) -> int:
    """Index of the last newline that ends a record (quotes before it balance), or -1."""
    cut = data.rfind(b"\n")
    if cut < 0 or b'"' not in data:
        return cut
    odd = data.count(b'"', 0, cut) & 1
    for _ in range(max_lines):
        if not odd or cut < 0:
            break
        prev = data.rfind(b"\n", 0, cut)
        odd ^= data.count(b'"', prev + 1, cut) & 1
        cut = prev
    return cut if not odd else -1


def _line_spans(buf):
    """Start and end (exclusive, without the newline) of every line of a block ending with a newline."""
    nl = np.flatnonzero(buf == 10)
    ends = nl
    starts = np.empty_like(nl)
    if nl.size:
        starts[0] = 0
        starts[1:] = nl[:-1] + 1
    if buf.size and buf[-1] != 10:
        starts = np.append(starts, nl[-1] + 1 if nl.size else 0)
        ends = np.append(ends, buf.size)
    return starts, ends


def _split_records(block: bytes, first_line: int, ncols: int):
    """Records of a block: ``(good_bytes, lines, rejects)``.

    ``lines`` are the first file lines of the good records, in order;
    ``rejects`` the records with the wrong field count or an unclosed quote.
    ``good_bytes`` is ``block`` itself when every record is good.
    """
    buf = np.frombuffer(block, dtype=np.uint8)
    starts, ends = _line_spans(buf)
    line_no = np.arange(first_line, first_line + starts.size, dtype=np.int64)
    rejects = []
    if b'"' in block:
        # records may span lines: a line ends a record when the quotes before it balance
        q = np.cumsum(buf == 34, dtype=np.int64)
        before = np.concatenate([[0], q])
        odd = ((before[ends] - before[starts]) & 1) == 1
        if odd.any():
            return _split_quoted(block, first_line, ncols)
        comma_mask = (buf == 44) & ((q & 1) == 0)
    else:
        comma_mask = buf == 44
    commas = np.flatnonzero(comma_mask)
    nfields = np.searchsorted(commas, ends) - np.searchsorted(commas, starts) + 1
    length = ends - starts
    empty = length == 0
    if buf.size:
        empty |= (length == 1) & (buf[np.minimum(starts, buf.size - 1)] == 13)
    bad = (nfields != ncols) & ~empty
    keep = ~empty & ~bad
    if bad.any():
        for i in np.flatnonzero(bad):
            raw = block[starts[i]:ends[i]]
            rejects.append(Reject(int(line_no[i]), f"expected {ncols} fields, got {int(nfields[i])}",
                                  _raw_text(raw)))
        good = [block[s:e + 1] for s, e in zip(starts[keep], ends[keep])]
        good = [g if g.endswith(b"\n") else g + b"\n" for g in good]
        return good, line_no[keep], rejects
    return block, line_no[keep], rejects


def _split_quoted(block: bytes, first_line: int, ncols: int):
    """Slow path for blocks with quoted newlines or unbalanced quotes: Python's csv state machine.

    A record whose quote does not close within a few lines, or that has the
    wrong number of fields, is rejected from its first line ("unclosed quote"
    when a quote is open at its end) and reading resumes on the next line.
    """
    import csv

    lines = block.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    good, good_lines, rejects = [], [], []
    i = 0
    n = len(lines)
    while i < n:
        line = lines[i]
        if line in (b"", b"\r"):
            i += 1
            continue
        # gather lines while the quotes are unbalanced (at most 1,000 lines per record)
        j = i
        rec = line
        while rec.count(b'"') % 2 == 1 and j + 1 < n and j - i < 1000:
            j += 1
            rec = rec + b"\n" + lines[j]
        if rec.count(b'"') % 2 == 1:
            rejects.append(Reject(first_line + i, "unclosed quote", _raw_text(line)))
            i += 1
            continue
        try:
            fields = next(csv.reader([rec.decode("utf-8", "surrogateescape")], strict=True))
        except (csv.Error, StopIteration):
            rejects.append(Reject(first_line + i, "bad quoting", _raw_text(line)))
            i += 1
            continue
        if len(fields) != ncols:
            if j > i:
                rejects.append(Reject(first_line + i, "unclosed quote", _raw_text(line)))
                i += 1
            else:
                rejects.append(Reject(first_line + i, f"expected {ncols} fields, got {len(fields)}",
                                      _raw_text(line)))
                i += 1
            continue
        good.append(rec + b"\n")
        good_lines.append(first_line + i)
        i = j + 1
    return good, np.asarray(good_lines, dtype=np.int64), rejects


def _raw_text(raw: bytes) -> str:
    return raw.rstrip(b"\r").decode("utf-8", "backslashreplace")[:RAW_MAX]


def _parse_block(path, block: bytes, first_line: int, schema, nnl=None):
    """One block of records as a Table with ``__line__`` plus its rejects.

    Fast path: pyarrow parses the block with the declared types; when it
    finds exactly one well-formed row per line, row ``k`` is on line
    ``first_line + k``. Anything else (a short or long row, a blank line, a
    quoted newline, a value that does not convert) sends the block to the
    slow path, which splits records itself and converts column by column.
    """
    import pyarrow as pa
    import pyarrow.csv as pcsv

    names = schema.names
    nlines = (block.count(b"\n") if nnl is None else nnl) + (0 if block.endswith(b"\n") else 1)
    try:
        table = pcsv.read_csv(pa.py_buffer(block), read_options=pcsv.ReadOptions(column_names=names),
                              convert_options=pcsv.ConvertOptions(column_types=schema))
        if table.num_rows == nlines:  # a short or long row raised ArrowInvalid: slow path
            lines = np.arange(first_line, first_line + nlines, dtype=np.int64)
            return table.append_column(LINE_COL, pa.array(lines)), []
    except pa.ArrowInvalid:
        pass
    good, lines, rejects = _split_records(block, first_line, len(names))
    data = b"".join(good) if isinstance(good, list) else good
    if not lines.size:
        return pa.schema(list(schema) + [pa.field(LINE_COL, pa.int64())]).empty_table(), rejects
    quoted = b'"' in data
    popts = pcsv.ParseOptions(newlines_in_values=quoted)
    try:
        table = pcsv.read_csv(pa.py_buffer(data), read_options=pcsv.ReadOptions(column_names=names),
                              parse_options=popts, convert_options=pcsv.ConvertOptions(column_types=schema))
        if table.num_rows != lines.size:
            raise ValueError("record count mismatch")
    except (pa.ArrowInvalid, ValueError):
        table, lines, more = _parse_block_slow(data, lines, schema, names, quoted)
        rejects = sorted(rejects + more, key=lambda r: r.line)
    return table.append_column(LINE_COL, pa.array(lines)), rejects


def _parse_block_slow(data: bytes, lines, schema, names, quoted):
    """Parse every column as bytes, then convert column by column; rows that do not fit are rejects."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    raw = pcsv.read_csv(pa.py_buffer(data),
                        read_options=pcsv.ReadOptions(column_names=names, use_threads=True),
                        parse_options=pcsv.ParseOptions(newlines_in_values=quoted, ignore_empty_lines=True),
                        convert_options=pcsv.ConvertOptions(column_types={n: pa.binary() for n in names}))
    if raw.num_rows != lines.size:
        raise HpeError(f"cannot split lines {lines[0]}-{lines[-1]} into records consistently")
    n = raw.num_rows
    reason = np.full(n, None, dtype=object)
    arrays = []
    for name in names:
        col = raw.column(name).combine_chunks()
        typ = schema.field(name).type
        arr, bad, why = _convert_column(col, typ, name)
        first = bad & (reason == None)  # noqa: E711
        reason[first] = why[first] if isinstance(why, np.ndarray) else why
        arrays.append(arr)
    ok = reason == None  # noqa: E711
    rejects = []
    if not ok.all():
        recs = _records_text(data, quoted)
        for i in np.flatnonzero(~ok):
            rejects.append(Reject(int(lines[i]), reason[i], _raw_text(recs[i]) if i < len(recs) else ""))
    mask = pa.array(ok)
    table = pa.Table.from_arrays([a.filter(mask) for a in arrays], schema=schema)
    return table, lines[ok], rejects


def _records_text(data: bytes, quoted: bool):
    if not quoted:
        return [ln for ln in data.split(b"\n") if ln not in (b"", b"\r")]
    return _quoted_records(data)


def _quoted_records(data: bytes):
    """Raw bytes of each record of a block whose records are all well formed."""
    out, rec = [], b""
    for line in data.split(b"\n"):
        rec = line if not rec else rec + b"\n" + line
        if rec.count(b'"') % 2 == 0:
            if rec not in (b"", b"\r"):
                out.append(rec)
            rec = b""
    return out


def _convert_column(col, typ, name):
    """Binary column -> (array of ``typ`` with bad rows null, bad mask, reason)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    n = len(col)
    bad = np.zeros(n, dtype=bool)
    # 1. UTF-8
    try:
        s = pc.cast(col, pa.string())
    except pa.ArrowInvalid:
        bad_utf8 = np.array([v is not None and not _is_utf8(v) for v in col.to_pylist()], dtype=bool)
        bad |= bad_utf8
        col = pc.if_else(pa.array(bad_utf8), pa.scalar(b"", pa.binary()), col)
        s = pc.cast(col, pa.string())
    why = np.full(n, None, dtype=object)
    why[bad] = f"undecodable bytes in {name} (not UTF-8)"
    if pa.types.is_string(typ) or pa.types.is_large_string(typ):
        return s, bad, why
    # 2. null tokens, as pyarrow's CSV reader treats them
    null = np.asarray(pc.is_in(s, value_set=pa.array(_null_values())).to_numpy(zero_copy_only=False), dtype=bool)
    null |= np.asarray(s.is_null().to_numpy(zero_copy_only=False), dtype=bool)
    s = pc.if_else(pa.array(null | bad), pa.scalar(None, pa.string()), s)
    if pa.types.is_floating(typ) or pa.types.is_integer(typ):
        nodigit = ~np.asarray(pc.match_substring_regex(s, r"[0-9]|(?i:nan|inf)").fill_null(True)
                              .to_numpy(zero_copy_only=False), dtype=bool)
        if nodigit.any():
            bad |= nodigit
            s = pc.if_else(pa.array(nodigit), pa.scalar(None, pa.string()), s)
    failed = _failing(s, typ)
    if failed.any():
        bad |= failed
        s = pc.if_else(pa.array(failed), pa.scalar(None, pa.string()), s)
    newly = bad & (why == None)  # noqa: E711
    if pa.types.is_floating(typ):
        why[newly] = f"non-numeric value in {name}"
    else:
        why[newly] = f"value in {name} does not fit the column's type {typ} (inferred from the first rows)"
    return pc.cast(s, typ), bad, why


def _is_utf8(v: bytes) -> bool:
    try:
        v.decode("utf-8")
        return True
    except UnicodeDecodeError:
        return False


def _failing(s, typ) -> np.ndarray:
    """Rows of string array ``s`` that do not cast to ``typ`` (bisection: a few casts per bad value)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    out = np.zeros(len(s), dtype=bool)

    def go(lo, hi):
        try:
            pc.cast(s.slice(lo, hi - lo), typ)
            return
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            pass
        if hi - lo == 1:
            out[lo] = True
            return
        if hi - lo <= 16:
            for i in range(lo, hi):
                go(i, i + 1)
            return
        mid = (lo + hi) // 2
        go(lo, mid)
        go(mid, hi)

    if len(s):
        go(0, len(s))
    return out


# ----------------------------------------------------------------------------------------------- datasets
def _read_dataset(path: Path):
    """A dataset folder or archive as a pandas label table, or None for plain tables.

    ``.mat`` files (300W-LP/AFLW2000, angles in degrees in the ``300w_lp``
    system; the 300W-LP root or ``300W-LP.zip``, see :mod:`hpe_cli.datasets.w300lp`),
    BIWI pose files / ``db_annotations.tgz`` (angles in the ``biwi`` system,
    see :mod:`hpe_cli.datasets.biwi`) or DAD-3DHeads (``dad3dheads`` matrices,
    see :mod:`hpe_cli.datasets.dad3dheads`). The table's ``attrs["system"]``
    names the system of its labels.
    """
    name = path.name.lower()
    if path.is_file() and name.endswith(".mat"):
        from ..datasets.mat import read_mat_dir

        return read_mat_dir(path)
    if path.is_file() and name.endswith(".zip"):
        from ..datasets.w300lp import is_w300lp_zip, open_w300lp

        if is_w300lp_zip(path):
            return open_w300lp(path)
        raise HpeError(f"{path}: expected a 300W-LP zip with AFW/HELEN/IBUG/LFPW .mat members")
    is_biwi_file = path.is_file() and (name.endswith((".tgz", ".tar.gz")) or
                                       (name.startswith("frame_") and name.endswith(("_pose.txt", "_pose.bin"))))
    if path.is_dir() and any(path.glob("*.mat")):
        from ..datasets.mat import read_mat_dir

        return read_mat_dir(path)
    if path.is_dir():
        from ..datasets.w300lp import is_w300lp_root, open_w300lp

        if is_w300lp_root(path):
            return open_w300lp(path)
    from ..datasets.dad3dheads import is_dad3dheads, read_dad3dheads

    if is_dad3dheads(path):
        return read_dad3dheads(path)
    if is_biwi_file or (path.is_dir() and next(path.rglob("frame_*_pose.*"), None) is not None):
        from ..datasets.biwi import read_biwi

        table = read_biwi(path)
        out = table[["file", "sequence", "frame", "pitch", "yaw", "roll", "center_x", "center_y", "center_z"]].copy()
        # the key of each row: sequence + frame, and the RGB frame they label (BIWI's NN/frame_XXXXX_rgb.png)
        out.insert(1, "image", [f"{s}/frame_{int(f):05d}_rgb.png" for s, f in zip(out["sequence"], out["frame"])])
        out.attrs["system"] = "biwi"
        return out
    if path.is_dir():
        raise HpeError(f"{path}: no .mat files, 300W-LP subset folders, DAD-3DHeads annotations or BIWI "
                       "frame_XXXXX_pose.txt/.bin files found")
    return None


def read_table(path):
    """Read a whole label table into a pandas DataFrame (small inputs, tests)."""
    import pyarrow as pa

    src = open_table(path)
    batches = list(src.batches())
    return pa.Table.from_batches(batches, schema=src.schema).to_pandas()
