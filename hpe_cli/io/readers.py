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


def open_table(path, batch_size: int = DEFAULT_BATCH) -> TableSource:
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
    if dataset is not None:
        table = pa.Table.from_pandas(dataset, preserve_index=False)
        return TableSource(path, table.schema, table.num_rows, lambda: iter(table.to_batches(batch_size)))
    suffix = path.suffix.lower()
    if path.stat().st_size == 0:
        raise HpeError(f"{path}: empty file")
    try:
        if suffix in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            pf = pq.ParquetFile(path)
            return TableSource(path, pf.schema_arrow, pf.metadata.num_rows,
                               lambda: pf.iter_batches(batch_size=batch_size))
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
    system) or BIWI pose files / ``db_annotations.tgz`` (angles in the
    ``biwi`` system, see :mod:`hpe_cli.datasets.biwi`).
    """
    name = path.name.lower()
    if path.is_file() and name.endswith(".mat"):
        from ..datasets.mat import read_mat_dir

        return read_mat_dir(path)
    is_biwi_file = path.is_file() and (name.endswith((".tgz", ".tar.gz")) or
                                       (name.startswith("frame_") and name.endswith(("_pose.txt", "_pose.bin"))))
    if path.is_dir() and any(path.glob("*.mat")):
        from ..datasets.mat import read_mat_dir

        return read_mat_dir(path)
    if is_biwi_file or (path.is_dir() and next(path.rglob("frame_*_pose.*"), None) is not None):
        from ..datasets.biwi import read_biwi

        table = read_biwi(path)
        return table[["file", "sequence", "frame", "pitch", "yaw", "roll", "center_x", "center_y", "center_z"]]
    if path.is_dir():
        raise HpeError(f"{path}: no .mat files or BIWI frame_XXXXX_pose.txt/.bin files found")
    return None


def read_table(path):
    """Read a whole label table into a pandas DataFrame (small inputs, tests)."""
    import pyarrow as pa

    src = open_table(path)
    batches = list(src.batches())
    return pa.Table.from_batches(batches, schema=src.schema).to_pandas()
