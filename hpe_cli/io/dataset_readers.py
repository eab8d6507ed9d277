"""The table of input readers: dataset folders and archives, and the named label lists of ``--input-format``.

Every reader is a :class:`DatasetReader` in :data:`READERS`: a cheap ``detect(path)``, an ``open`` that returns a
:class:`~hpe_cli.io.table_source.TableSource`, and what the docs say of it (the system its labels are in, the
key columns that name a row, the landmark scheme). :func:`hpe_cli.io.readers.open_table` asks the readers in
registration order (the named lists first, then the datasets) and the first one that detects the path reads it;
``--input-format NAME`` picks a named list directly. Built-in readers register themselves in
:mod:`hpe_cli.io.columns` (the named lists) and :mod:`hpe_cli.io.readers_datasets` (the datasets); a plug-in
calls :func:`register_reader` (see the "Extending hpe" page of the docs).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..registry import Registry


@dataclass(frozen=True)
class DatasetReader:
    """One input reader.

    Attributes
    ----------
    name : str
        The reader's name (``--input-format NAME`` for a named list).
    detect : callable
        ``detect(path: Path) -> bool``: this reader takes ``path`` (from its name, its first bytes, a folder's
        entries; cheap, it runs for every input that earlier readers did not take).
    open : callable
        ``open(path: Path, *, batch_size: int, with_lines: bool) -> TableSource or None``: the labels, streamed;
        None when a closer look shows the file is not this reader's after all (the next readers are asked).
        Bad input raises :class:`~hpe_cli.errors.HpeError` naming the file and where.
    system : str or None
        The rotation system of the labels (None: the file or ``--system`` says).
    key : tuple of str
        Columns that name a row (``--key`` of ``hpe evaluate``).
    landmarks : str or None
        The 2-D landmark scheme of ``lm{i}_x, lm{i}_y`` (``ibug68``...), None when the reader has none.
    doc : str
        One line for the docs: what the reader takes.
    input_format : bool
        A named label list, chosen with ``--input-format NAME`` (a file only).
    """

    name: str
    detect: Callable
    open: Callable
    system: str | None = None
    key: tuple = ()
    landmarks: str | None = None
    doc: str = ""
    input_format: bool = False


#: name -> :class:`DatasetReader`, in the order :func:`open_dataset` asks them
READERS = Registry("dataset reader", loader="hpe_cli.io.readers_builtin")


def register_reader(
    name: str,
    detect: Callable,
    *,
    system: str | None = None,
    key: tuple = (),
    landmarks: str | None = None,
    doc: str = "",
    input_format: bool = False,
) -> Callable:
    """Decorator: register ``open(path, *, batch_size, with_lines) -> TableSource`` as the reader ``name``.

    ``detect(path) -> bool`` says which inputs it takes; the other arguments are the :class:`DatasetReader`
    attributes. Returns ``open`` unchanged.
    """

    def add(open_: Callable) -> Callable:
        READERS.register(name, DatasetReader(name, detect, open_, system, tuple(key), landmarks, doc, input_format))
        return open_

    return add


def input_format_names() -> tuple:
    """The readers ``--input-format`` names (the named label lists), in order."""
    return READERS.filter(lambda r: r.input_format)


def find_reader(path) -> DatasetReader | None:
    """The first reader whose ``detect`` takes ``path``, or None."""
    path = Path(path)
    for reader in list(READERS.values()):
        if reader.detect(path):
            return reader
    return None


def open_dataset(path, *, batch_size: int, with_lines: bool = False):
    """``path`` opened by the first reader that detects it and reads it, or None (a plain Parquet/CSV table)."""
    path = Path(path)
    for reader in list(READERS.values()):
        if reader.detect(path):
            src = reader.open(path, batch_size=batch_size, with_lines=with_lines)
            if src is not None:
                return src
    return None
