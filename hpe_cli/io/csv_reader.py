"""The CSV fast path: blocks of whole records parsed by pyarrow, bad records set aside with their file line.

See :mod:`hpe_cli.io.readers` for the row numbering and the reject rules."""

from __future__ import annotations

import csv

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv

from ..errors import HpeError
from .table_source import (
    LINE_COL,
    RAW_MAX,
    Reject,
    TableSource,
    check_duplicates,
    float_columns,
    is_float_column,
    table_schema,
)


def open_csv(path, batch_size, with_lines, block_size):

    reader = _CsvBlocks(path, block_size)
    header, header_lines = reader.header()
    names = _parse_header(path, header)
    check_duplicates(path, names)
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

    return TableSource(path, table_schema(schema, with_lines), None, gen, with_lines, "csv")


def _parse_header(path, header: bytes) -> list:

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
        header, self._rest = first[: cut + 1], first[cut + 1 :]
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
                block, self._rest = data[: cut + 1], data[cut + 1 :]
            nnl = block.count(b"\n")
            yield block, self._line, nnl
            self._line += nnl
            if eof:
                break
        f.close()

    def infer_schema(self, names, first_line):
        """Column types from the first block: float columns forced to float64, null columns to string."""

        self.ncols = len(names)
        floats = float_columns()
        for block, line, _ in self.raw_blocks():
            types = {n: pa.string() for n in names if is_float_column(n, floats)}
            t = None
            for attempt in range(2):
                if attempt:
                    good, _, _ = _split_records(block, line, len(names))
                    block = b"".join(good) if isinstance(good, list) else good
                try:
                    # a small probe is parsed on this thread: no Arrow pool threads start for a file that a
                    # command may reject a moment later (threads still starting at exit abort the process)
                    ropts = pcsv.ReadOptions(column_names=names, use_threads=len(block) > (4 << 20))
                    t = pcsv.read_csv(
                        pa.py_buffer(block),
                        read_options=ropts,
                        parse_options=pcsv.ParseOptions(newlines_in_values=b'"' in block),
                        convert_options=pcsv.ConvertOptions(column_types=types),
                    )
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
            raw = block[starts[i] : ends[i]]
            rejects.append(Reject(int(line_no[i]), f"expected {ncols} fields, got {int(nfields[i])}", _raw_text(raw)))
        good = [block[s : e + 1] for s, e in zip(starts[keep], ends[keep])]
        good = [g if g.endswith(b"\n") else g + b"\n" for g in good]
        return good, line_no[keep], rejects
    return block, line_no[keep], rejects


def _split_quoted(block: bytes, first_line: int, ncols: int):
    """Slow path for blocks with quoted newlines or unbalanced quotes: Python's csv state machine.

    A record whose quote does not close within a few lines, or that has the
    wrong number of fields, is rejected from its first line ("unclosed quote"
    when a quote is open at its end) and reading resumes on the next line.
    """

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
                rejects.append(Reject(first_line + i, f"expected {ncols} fields, got {len(fields)}", _raw_text(line)))
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

    names = schema.names
    nlines = (block.count(b"\n") if nnl is None else nnl) + (0 if block.endswith(b"\n") else 1)
    try:
        table = pcsv.read_csv(
            pa.py_buffer(block),
            read_options=pcsv.ReadOptions(column_names=names),
            convert_options=pcsv.ConvertOptions(column_types=schema),
        )
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
        table = pcsv.read_csv(
            pa.py_buffer(data),
            read_options=pcsv.ReadOptions(column_names=names),
            parse_options=popts,
            convert_options=pcsv.ConvertOptions(column_types=schema),
        )
        if table.num_rows != lines.size:
            raise ValueError("record count mismatch")
    except (pa.ArrowInvalid, ValueError):
        table, lines, more = _parse_block_slow(data, lines, schema, names, quoted)
        rejects = sorted(rejects + more, key=lambda r: r.line)
    return table.append_column(LINE_COL, pa.array(lines)), rejects


def _parse_block_slow(data: bytes, lines, schema, names, quoted):
    """Parse every column as bytes, then convert column by column; rows that do not fit are rejects."""

    raw = pcsv.read_csv(
        pa.py_buffer(data),
        read_options=pcsv.ReadOptions(column_names=names, use_threads=True),
        parse_options=pcsv.ParseOptions(newlines_in_values=quoted, ignore_empty_lines=True),
        convert_options=pcsv.ConvertOptions(column_types={n: pa.binary() for n in names}),
    )
    if raw.num_rows != lines.size:
        raise HpeError(f"cannot split lines {lines[0]}-{lines[-1]} into records consistently")
    n = raw.num_rows
    reason = np.full(n, None, dtype=object)
    arrays = []
    for name in names:
        col = raw.column(name).combine_chunks()
        typ = schema.field(name).type
        arr, bad, why = _convert_column(col, typ, name)
        first = bad & (reason == None)
        reason[first] = why[first] if isinstance(why, np.ndarray) else why
        arrays.append(arr)
    ok = reason == None
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
    import pyarrow.compute as pc  # lazy: start-up

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
        nodigit = ~np.asarray(
            pc.match_substring_regex(s, r"[0-9]|(?i:nan|inf)").fill_null(True).to_numpy(zero_copy_only=False),
            dtype=bool,
        )
        if nodigit.any():
            bad |= nodigit
            s = pc.if_else(pa.array(nodigit), pa.scalar(None, pa.string()), s)
    failed = _failing(s, typ)
    if failed.any():
        bad |= failed
        s = pc.if_else(pa.array(failed), pa.scalar(None, pa.string()), s)
    newly = bad & (why == None)
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
    import pyarrow.compute as pc  # lazy: start-up

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
