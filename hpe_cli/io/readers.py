"""Streaming table readers: Parquet, CSV, or a folder of 300W-LP/AFLW2000 ``.mat`` files."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from ..errors import HpeError

DEFAULT_BATCH = 262_144


@dataclass
class TableSource:
    """A table read lazily in record batches."""

    path: Path
    schema: object
    num_rows: int | None
    _batches: Callable[[], Iterator]
    #: rotation system the reader's labels are in ("300w_lp" for .mat, "biwi", "dad3dheads", a Parquet
    #: file's hpe:system metadata), or None when the file does not say
    system: str | None = None
    #: True when a dataset reader (.mat, 300W-LP, BIWI, DAD-3DHeads) produced the labels: their system is
    #: fixed by the dataset, whatever a command's --system says
    dataset: bool = False

    @property
    def columns(self) -> list:
        return list(self.schema.names)

    def batches(self) -> Iterator:
        """Yield pyarrow RecordBatches; a parse error mid-file becomes an HpeError."""
        import pyarrow as pa

        try:
            yield from self._batches()
        except (pa.ArrowInvalid, OSError, ValueError) as exc:
            raise HpeError(f"{self.path}: cannot read: {_one_line(exc)}") from None


def _one_line(exc) -> str:
    return " ".join(str(exc).split())[:300]


def open_table(path, batch_size: int = DEFAULT_BATCH, columns=None, delimiter=None, header: bool = True,
               input_format=None, names=None, with_lines: bool = False) -> TableSource:
    """Open a label table for streaming.

    ``columns`` renames columns (``"pitch=Pitch,yaw=Yaw"`` or ``{"pitch": "Pitch"}``);
    ``delimiter``/``header``/``names`` read delimited text of any suffix;
    ``input_format`` names a label list (see :mod:`hpe_cli.io.columns`); COCO
    ``.json`` and WHENet ``annotation.txt`` are recognised without it.
    """
    from .columns import active_table_options, apply_columns_map, open_formatted

    if columns is None and delimiter is None and header and input_format is None and names is None:
        active = active_table_options()  # the running command's --columns-map/--delimiter/... options
        if active:
            columns, delimiter, header = active["columns"], active["delimiter"], active["header"]
            input_format, names = active["input_format"], active["names"]
    src = open_formatted(path, batch_size, input_format=input_format, delimiter=delimiter, header=header,
                         names=names, with_lines=with_lines)
    if src is None:
        src = _open_core(path, batch_size)
    return apply_columns_map(src, columns)


def _open_core(path, batch_size: int = DEFAULT_BATCH) -> TableSource:
    """Open a label table for streaming.

    ``path`` may be ``.parquet``/``.pq``, ``.csv``, a folder of ``.mat`` files
    (read from ``Pose_Para``, see :func:`hpe_cli.datasets.mat.read_mat_dir`), or
    BIWI pose files (a folder, one file, or ``db_annotations.tgz``; angles in
    the ``biwi`` system).
    """
    import pyarrow as pa

    path = Path(path)
    if not path.exists():
        raise HpeError(f"{path}: no such file or folder")
    dataset = _read_dataset(path)
    if isinstance(dataset, TableSource):  # a dataset reader that streams
        return dataset
    if dataset is not None:
        system = dataset.attrs.get("system")
        table = pa.Table.from_pandas(dataset, preserve_index=False)
        return TableSource(path, table.schema, table.num_rows, lambda: iter(table.to_batches(batch_size)), system,
                           dataset=system is not None)
    suffix = path.suffix.lower()
    if path.stat().st_size == 0:
        raise HpeError(f"{path}: empty file")
    try:
        if suffix in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            pf = pq.ParquetFile(path)
            meta = pf.schema_arrow.metadata or {}
            system = meta[b"hpe:system"].decode("utf-8", "replace") if b"hpe:system" in meta else None
            return TableSource(path, pf.schema_arrow, pf.metadata.num_rows,
                               lambda: pf.iter_batches(batch_size=batch_size), system)
        if suffix == ".csv":
            import pyarrow.csv as pcsv

            reader = pcsv.open_csv(path, read_options=pcsv.ReadOptions(block_size=1 << 24))
            return TableSource(path, reader.schema, None, lambda: iter(reader))
    except (pa.ArrowInvalid, OSError) as exc:
        raise HpeError(f"{path}: cannot read: {_one_line(exc)}") from None
    raise HpeError(f"{path}: expected a .parquet, .csv or .mat file or a folder of .mat files, got {suffix or 'no extension'!r}")


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
        out = table[["file", "sequence", "frame", "pitch", "yaw", "roll", "center_x", "center_y", "center_z"]]
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
