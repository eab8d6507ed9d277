"""The rejects file: every input row that was not labelled, with its reason."""
from __future__ import annotations

from collections import Counter

import numpy as np

from .writers import check_output, write_table


class Rejects:
    """Collect rejected rows (as column dicts) and write them once, atomically.

    ``path=None`` still counts reasons, so a summary can always be printed.
    """

    def __init__(self, path=None, overwrite: bool = False):
        self.path = check_output(path, overwrite) if path else None
        self.overwrite = overwrite
        self._parts: list = []
        self.counts: Counter = Counter()

    def __len__(self) -> int:
        return sum(self.counts.values())

    def add(self, columns: dict, reasons) -> None:
        """Add rows: ``columns`` maps name -> 1-D array, ``reasons`` is one string per row."""
        reasons = np.asarray(reasons, dtype=object)
        if reasons.size == 0:
            return
        self.counts.update(reasons.tolist())
        if self.path is not None:
            self._parts.append({**{k: np.asarray(v) for k, v in columns.items()}, "reason": reasons})

    def first(self) -> str | None:
        return next(iter(self.counts), None)

    def write(self):
        if self.path is None:
            return None
        import pandas as pd

        frame = pd.concat([pd.DataFrame(p) for p in self._parts], ignore_index=True) if self._parts \
            else pd.DataFrame({"reason": pd.Series([], dtype=str)})
        return write_table(frame, self.path, overwrite=self.overwrite)
