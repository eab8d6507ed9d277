"""``--exclude FILE``: drop the rows a key list names (``hpe audit --consistency --suspects`` writes one).

The file is a table (.csv or .parquet) with a ``reason`` column and key columns
(any of ``file, image, image_id, id, path, sequence, frame, camera, person_id``);
``row`` and ``score`` are information, not keys. A row of the input is excluded
when its values equal a listed row's in every key column the input has (compared
as text: ``108`` equals ``108``, whatever the integer width). Matching runs in
Arrow on whole columns (one joined key string per row, ``is_in``).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from ..errors import HpeError, UsageError
from .readers import open_table

KEY_COLUMNS = ("file", "image", "image_id", "id", "path", "sequence", "frame", "camera", "person_id")
SEP = "\x1f"


def _key_strings(table, keys):
    import pyarrow.compute as pc  # lazy: start-up

    cols = []
    for k in keys:
        c = table.column(k)
        if pa.types.is_floating(c.type):  # a key read as float (CSV with gaps): 108.0 -> 108
            ints = pc.cast(c, pa.int64(), safe=False)
            c = pc.if_else(pc.equal(pc.cast(ints, c.type), c), pc.cast(ints, pa.string()), pc.cast(c, pa.string()))
        cols.append(pc.fill_null(pc.cast(c, pa.string()), ""))
    if len(cols) == 1:
        return cols[0]
    return pc.binary_join_element_wise(*cols, SEP)


def _filled(s) -> bool:
    """True when a pandas column has a value other than null, "" and -1."""
    empty = s.isna() | (s == -1) if s.dtype.kind in "iuf" else s.isna() | (s.astype(str) == "")
    return not bool(empty.all())


class ExcludeList:
    """The key list of ``path``; :meth:`reasons` names the excluded rows of a table."""

    def __init__(self, path):

        src = open_table(path)
        self.path = src.path

        batches = list(src.batches())
        table = pa.Table.from_batches(batches, schema=src.schema) if batches else src.schema.empty_table()
        if "reason" not in table.column_names:
            raise HpeError(f"{self.path}: expected a 'reason' column (a key list from `hpe audit --suspects`)")
        self.keys = [c for c in KEY_COLUMNS if c in table.column_names]
        if not self.keys:
            raise HpeError(f"{self.path}: expected key columns (some of {', '.join(KEY_COLUMNS)}), got none")
        self.table = table

    def __len__(self) -> int:
        return self.table.num_rows

    def check_input(self, names) -> list:
        """The key columns the input (column ``names``) shares with the list; a usage error naming the list
        when there are none (the list was made for another table)."""
        keys = [k for k in self.keys if k in names]
        if not keys:
            shown = [n for n in names if not n.startswith("__")][:12]
            raise UsageError(
                f"{self.path}: none of its key columns ({', '.join(self.keys)}) is in the input; "
                f"expected some of: {', '.join(shown)}"
            )
        return keys

    def reasons(self, table) -> np.ndarray:
        """``"excluded: <reason>"`` for each listed row of ``table`` (Arrow table/batch), ``""`` for the others."""
        import pyarrow.compute as pc  # lazy: start-up

        keys = self.check_input(table.schema.names)
        listed = _key_strings(self.table, keys)
        here = _key_strings(table, keys)
        idx = pc.index_in(here, value_set=listed).fill_null(-1).to_numpy(zero_copy_only=False)
        why = np.array([f"excluded: {r}" for r in self.table.column("reason").to_pylist()] + [""], dtype=object)
        return why[np.where(idx < 0, len(why) - 1, idx)]

    def reasons_frame(self, frame) -> np.ndarray:
        """:meth:`reasons` of a pandas DataFrame."""

        # a key column holding only the readers' placeholders ("" or -1: the input has no such column) is absent
        have = [k for k in KEY_COLUMNS if k in frame.columns and (len(frame) == 0 or _filled(frame[k]))]
        cols = self.check_input(have)
        return self.reasons(pa.Table.from_pandas(frame[cols], preserve_index=False))
