"""Streaming table readers: Parquet, CSV, and the dataset readers of :data:`~hpe_cli.io.dataset_readers.READERS`.

Memory does not depend on the number of rows: Parquet is read one record
batch at a time without pre-buffering, CSV in bounded blocks of bytes.

Row numbers (one rule, :meth:`TableSource.where`)
-------------------------------------------------
Every row has a 1-based number in ``__line__``, and every message and rejects
file uses it: for text files it is the file line where the record starts
(``FILE: line N``; the header is line 1, blank lines count, a record with
quoted newlines counts from its first line); for Parquet, JSON and dataset
tables the 1-based row (``FILE: row N``); a row read from a one-record file
(a ``.mat`` of a folder, a BIWI pose file) is named by that file
(``FOLDER/NAME.mat: reason``).

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

from pathlib import Path

from ..errors import HpeError
from .table_source import (  # noqa: F401
    CSV_BLOCK,
    DEFAULT_BATCH,
    LINE_COL,
    RAW_MAX,
    Reject,
    TableSource,
    check_duplicates,
    is_float_column,
    one_line,
    table_schema,
    with_line_numbers,
)


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


def open_table(
    path,
    batch_size: int = DEFAULT_BATCH,
    columns=None,
    delimiter=None,
    header: bool = True,
    input_format=None,
    names=None,
    with_lines: bool = False,
    block_size: int | None = None,
) -> TableSource:
    """Open a label table for streaming.

    ``columns`` renames columns (``"pitch=Pitch,yaw=Yaw"`` or ``{"pitch": "Pitch"}``);
    ``delimiter``/``header``/``names`` read delimited text of any suffix;
    ``input_format`` names a label list (see :mod:`hpe_cli.io.columns`); COCO
    ``.json`` and WHENet ``annotation.txt`` are recognised without it. Without
    these arguments, the running command's ``--columns-map``/``--delimiter``/...
    options apply (:func:`hpe_cli.cli.table_options.column_options`).
    """
    from .columns import active_table_options, apply_columns_map, open_formatted  # lazy: start-up
    from .dataset_readers import open_dataset  # lazy: start-up

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
                from .columns import LenientMap  # lazy: start-up

                columns = LenientMap(columns)
    src = open_formatted(
        path,
        batch_size,
        input_format=input_format,
        delimiter=delimiter,
        header=header,
        names=names,
        with_lines=with_lines,
    )
    if src is None and Path(path).exists():
        src = open_dataset(path, batch_size=batch_size, with_lines=with_lines)
    if src is None:
        src = _open_core(path, batch_size, with_lines=with_lines, block_size=block_size or CSV_BLOCK)
    return apply_columns_map(src, columns)


def _open_core(
    path, batch_size: int = DEFAULT_BATCH, *, with_lines: bool = False, block_size: int = CSV_BLOCK
) -> TableSource:
    """Open a plain label table for streaming: Parquet or CSV (recognised by content, not by extension).

    Dataset folders and archives and the named label lists are read by the entries of
    :data:`hpe_cli.io.dataset_readers.READERS` before this is asked. With ``with_lines=True`` every batch
    carries an int64 ``__line__`` column (see the module docstring).
    """
    import pyarrow as pa  # lazy: start-up

    path = Path(path)
    if not path.exists():
        raise HpeError(f"{path}: no such file or folder")
    if path.is_dir():
        raise HpeError(
            f"{path}: no .mat files, 300W-LP subset folders, DAD-3DHeads annotations or BIWI "
            "frame_XXXXX_pose.txt/.bin files found"
        )
    if path.stat().st_size == 0:
        raise HpeError(f"{path}: empty file")
    kind = sniff(path)
    try:
        if kind == "parquet":
            return _open_parquet(path, batch_size, with_lines)
        if kind == "text":
            return _open_csv(path, batch_size, with_lines, block_size)
    except (pa.ArrowInvalid, OSError) as exc:
        raise HpeError(f"{path}: cannot read: {one_line(exc)}") from None
    what = {
        "pickle": "a Python pickle (hpe never loads pickles as tables; AGORA dataframes go to 'hpe relabel-agora')",
        "zip": "a zip archive",
        "gzip": "a gzip file (decompress it first)",
        "json": "JSON",
        "mat": "a MATLAB .mat file (give the .mat file or its folder with a .mat name)",
        "utf16": "UTF-16 text (save it as UTF-8)",
    }[kind]
    raise HpeError(f"{path}: expected a Parquet or CSV table, got {what}")


def _open_parquet(path, batch_size, with_lines):
    import pyarrow.parquet as pq  # lazy: start-up

    pf = pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20)
    schema = pf.schema_arrow
    check_duplicates(path, schema.names, where="")

    def gen():
        # one row group at a time, one batch at a time: nothing read is kept
        line = 1  # Parquet rows are named by their 1-based row ("FILE: row N")
        f = pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20)
        for rg in range(f.num_row_groups):
            for b in f.iter_batches(batch_size=batch_size, row_groups=[rg], use_threads=True):
                yield (with_line_numbers(b, line) if with_lines else b), []
                line += b.num_rows

    meta = schema.metadata or {}
    system = meta[b"hpe:system"].decode("utf-8", "replace") if b"hpe:system" in meta else None
    return TableSource(
        path,
        table_schema(schema, with_lines),
        pf.metadata.num_rows,
        gen,
        with_lines,
        "parquet",
        system=system,
        unit="row",
    )


def _open_csv(path, batch_size, with_lines, block_size):
    from .csv_reader import open_csv  # lazy: start-up

    return open_csv(path, batch_size, with_lines, block_size)


# ----------------------------------------------------------------------------------------------- datasets
def stream_source(path: Path, dataset, with_lines: bool) -> TableSource:
    """A dataset reader that streams (``iter_batches()``, ``schema``, ``num_rows``, ``system``) as a table;
    rows are named by their 1-based position."""

    def gen_stream():
        line = 1
        for b in dataset.iter_batches():
            yield with_line_numbers(b, line), []
            line += b.num_rows

    return TableSource(
        path,
        table_schema(dataset.schema, with_lines),
        dataset.num_rows,
        gen_stream,
        with_lines,
        "dataset",
        system=dataset.system,
        dataset=True,
        unit="row",
    )


def frame_source(path: Path, frame, batch_size: int, with_lines: bool) -> TableSource:
    """A dataset read whole as a pandas table, as a table source.

    ``frame.attrs``: ``system`` (the labels' system), ``one_record_files`` (a row is named by its ``file``, as
    the ``.mat`` files of a folder and BIWI pose files), ``bad_files`` (``(file, reason)`` of one-record files
    that could not be read: rejects named after the rows).
    """
    import pyarrow as pa  # lazy: start-up

    system = frame.attrs.get("system")
    row_files = [str(f) for f in frame["file"]] if frame.attrs.get("one_record_files") else None
    bad_files = frame.attrs.get("bad_files") or []
    rejected = [Reject(len(frame) + 1 + j, reason, str(f)) for j, (f, reason) in enumerate(bad_files)]
    if row_files is not None:
        row_files = row_files + [str(f) for f, _ in bad_files]
    table = pa.Table.from_pandas(frame, preserve_index=False)

    def gen():
        for start in range(0, max(table.num_rows, 1), batch_size):
            b = table.slice(start, batch_size).combine_chunks().to_batches()
            b = b[0] if b else pa.RecordBatch.from_pylist([], schema=table.schema)
            yield with_line_numbers(b, start + 1), (rejected if start == 0 else [])

    return TableSource(
        path,
        table_schema(table.schema, with_lines),
        table.num_rows,
        gen,
        with_lines,
        "dataset",
        system=system,
        dataset=system is not None,
        unit="file" if row_files else "row",
        row_files=row_files,
    )


def read_table(path):
    """Read a whole label table into a pandas DataFrame (small inputs, tests)."""
    import pyarrow as pa  # lazy: start-up

    src = open_table(path)
    batches = list(src.batches())
    return pa.Table.from_batches(batches, schema=src.schema).to_pandas()
