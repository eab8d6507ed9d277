"""A label table opened once: the stream, the rotation system it is read in, how its labels are stored.

Every command starts the same way: open the table, decide its rotation system (:func:`resolve_system`: the
file's own metadata, else the option, else the command's default), decide which columns hold the labels
(:func:`label_mode`). :func:`open_labels` does the three once and returns a :class:`LabelSource`; pipelines, the
Python API, the plots and the pages take that object (or a :class:`~hpe_cli.rotation.system_def.RotationSystem`)
and never resolve a system name again.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import HpeError
from .labels import label_mode
from .layout import ANGLE_COLS, MATRIX_COLS
from .readers import open_table
from .system_meta import Resolved, output_system, resolve_system
from .table_source import DEFAULT_BATCH, TableSource

#: ``mode=`` values besides a storage kind: pick the system's own columns, else angles, else r00..r22
AUTO = "auto"


@dataclass(frozen=True)
class LabelSource:
    """A label table opened once.

    Attributes
    ----------
    table : TableSource
        The stream of record batches (``batches()``, ``batches_with_rejects()``), its path and row naming.
    resolved : Resolved
        The system the labels are read in (``.system``), where it came from (``.origin``: ``"file metadata"``,
        ``"option"`` or ``"default"``) and the system the command writes or reports in (``.output``).
    mode : str
        How the labels are stored: ``"angles"`` (``pitch, yaw, roll``, degrees), ``"matrix"`` (``r00..r22``) or
        the system's own storage kind (``"rotvec"``, ``"quaternion"``, ``"6d"``...) for its own value columns.
    key : tuple of str
        The columns that name a row across tables (evaluate's join key, the audit's duplicate check); empty
        when the command has none.
    """

    table: TableSource
    resolved: Resolved
    mode: str
    key: tuple = ()

    @property
    def system(self):
        """The :class:`RotationSystem` the labels are read in."""
        return self.resolved.system

    @property
    def output_system(self):
        """The :class:`RotationSystem` the command writes or reports in (the read system unless converted)."""
        return output_system(self.resolved)

    @property
    def origin(self) -> str:
        """Where the system came from, with its note (``"file metadata; --from agrees"``)."""
        return self.resolved.origin_text

    @property
    def path(self) -> Path:
        return self.table.path

    @property
    def columns(self) -> list:
        return self.table.columns

    @property
    def num_rows(self):
        return self.table.num_rows

    @property
    def dataset(self) -> bool:
        """True when a dataset reader produced the rows (its format fixes the system)."""
        return bool(self.table.dataset)

    def where(self, n) -> str:
        """The name of row ``n`` in messages and rejects files (``FILE: line N``, ``FILE: row N``, ``FILE``)."""
        return self.table.where(n)

    def batches(self) -> Iterator:
        return self.table.batches()

    def batches_with_rejects(self) -> Iterator:
        return self.table.batches_with_rejects()


def check_mode(columns: Sequence, path, system, mode: str) -> str:
    """The label storage of ``columns``: ``mode`` checked, or found (:func:`label_mode`) when ``"auto"``.

    Raises
    ------
    HpeError
        ``mode`` names columns the table does not have.
    """
    if mode == AUTO:
        return label_mode(columns, path, system)
    cols = set(columns)
    if system is not None and system.storage_kind == mode and all(c in cols for c in system.value_columns):
        return mode
    need = ANGLE_COLS if mode == "angles" else MATRIX_COLS if mode == "matrix" else tuple(system.value_columns)
    missing = [c for c in need if c not in cols]
    if missing:
        raise HpeError(f"{path}: missing column(s) {', '.join(missing)} for --columns {mode}")
    return mode


def open_labels(
    path,
    system=None,
    *,
    default="300w_lp",
    option_name: str = "--system",
    option_is_output: bool = False,
    mode: str = AUTO,
    key: Sequence = (),
    batch_size: int = DEFAULT_BATCH,
    with_lines: bool = True,
    reinterpret=None,
) -> LabelSource:
    """Open a label table, resolve its rotation system and find its label columns, once.

    Parameters
    ----------
    path : str or Path
        Parquet, CSV/TSV/text, JSON (COCO, label lists), a ``.mat`` file or folder, a dataset folder.
    system : str, path or RotationSystem, optional
        The user's option (``--system``, ``--from``, ``--gt-system``...): the system for files that name none.
    default : str or None
        The command's default for files that name no system; None makes a missing ``system`` a usage error.
    option_name : str
        The option's spelling, for messages.
    option_is_output : bool
        ``system`` names what the command writes or reports in (draw, augment, evaluate, view): a dataset
        format's labels are then converted to it instead of the disagreement being an error.
    mode : str
        ``"auto"`` (the system's own columns, else angles, else ``r00..r22``) or a storage kind to insist on.
    key : sequence of str
        The row key columns (checked present).
    batch_size : int
        Rows per record batch.
    with_lines : bool
        Keep each row's line/row number (``__line__``) for messages and rejects.
    reinterpret : str, path or RotationSystem, optional
        ``--reinterpret-as``: read the labels in this system whatever the file says.

    Returns
    -------
    LabelSource
    """
    table = open_table(path, batch_size, with_lines=with_lines)
    return label_source(
        table,
        system,
        default=default,
        option_name=option_name,
        option_is_output=option_is_output,
        mode=mode,
        key=key,
        reinterpret=reinterpret,
    )


def label_source(
    table: TableSource,
    system=None,
    *,
    default="300w_lp",
    option_name: str = "--system",
    option_is_output: bool = False,
    mode: str = AUTO,
    key: Sequence = (),
    reinterpret=None,
) -> LabelSource:
    """:func:`open_labels` for a table already opened (a reader's own :class:`TableSource`)."""
    resolved = resolve_system(
        table,
        system,
        default=default,
        option_name=option_name,
        option_is_output=option_is_output,
        reinterpret=reinterpret,
    )
    found = check_mode(table.columns, table.path, resolved.system, mode)
    key = tuple(key)
    missing = [k for k in key if k not in table.columns]
    if missing:
        raise HpeError(f"{table.path}: missing key column(s) {', '.join(missing)}: found {', '.join(table.columns)}")
    return LabelSource(table, resolved, found, key)
