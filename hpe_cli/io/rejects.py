"""The rejects file: every input row that was not labelled, with its reason."""

from __future__ import annotations

from collections import Counter
from os.path import realpath

import numpy as np

from ..errors import HpeError, RejectedAllError
from .writers import check_output, write_table


def rejects_rule(count: int, first: str | None, *, has_file: bool, strict: bool, source=None) -> None:
    """The rule every command applies once its rows are processed (before anything is committed).

    Without a rejects file (``has_file=False``) or with ``strict``, any
    rejected row is an error: one line naming how many rows were set aside
    and the first one (``first``: ``"line N: reason"``), so the command exits 1
    and its output transaction writes nothing.
    """
    if not count:
        return
    where = f"{source}: " if source is not None else ""
    head = f"{where}{first}; " if first else where
    if strict:
        raise HpeError(f"{head}{count} row(s) rejected and --strict given: nothing written")
    if not has_file:
        raise HpeError(
            f"{head}{count} row(s) cannot be used: nothing written "
            "(use --rejects FILE to set them aside and write the rest)"
        )


class Rejects:
    """Collect rejected rows (as column dicts) and write them once, atomically.

    ``path=None`` still counts reasons, so a summary can always be printed.
    :meth:`finish` applies :func:`rejects_rule`: with rejected rows and no
    ``path`` (or ``strict``), it raises instead of writing, naming
    ``source`` and the first rejected row.
    """

    def __init__(self, path=None, overwrite: bool = False, strict: bool = False, source=None):
        self.path = check_output(path, overwrite) if path else None
        self.overwrite = overwrite
        self.strict = strict
        # a TableSource names its rows itself (FILE: line N / FILE: row N / FILE); a path gets "line N"
        self._where = getattr(source, "where", None)
        self.source = getattr(source, "path", source)
        self._named = False  # first_where already names the file
        self.first_where: str | None = None
        self._parts: list = []
        self.counts: Counter = Counter()

    def __len__(self) -> int:
        return sum(self.counts.values())

    def add(self, columns: dict, reasons, lines=None, where=None) -> None:
        """Add rows: ``columns`` maps name -> 1-D array, ``reasons`` is one string per row.

        ``lines`` (optional): the rows' ``__line__`` numbers, used to name the
        first rejected row (through the source's :meth:`~hpe_cli.io.readers.TableSource.where`
        when ``source`` was a TableSource: ``FILE: line N``, ``FILE: row N`` or
        ``FILE``); otherwise ``columns['line']`` or ``columns['row']`` is.
        ``where`` (optional): a callable naming a row number, or the name of
        the first row as a string, for rows of another table than ``source``.
        """
        reasons = np.asarray(reasons, dtype=object)
        if reasons.size == 0:
            return
        if self.first_where is None:
            n = next(
                (
                    int(np.asarray(v)[0])
                    for v in (lines, columns.get("line"), columns.get("row"))
                    if v is not None and np.asarray(v).size and _integral(np.asarray(v)[0])
                ),
                None,
            )
            locate = where if where is not None else self._where
            if isinstance(locate, str):
                self.first_where, self._named = f"{locate}: {reasons[0]}", True
            elif locate is not None and n is not None:
                self.first_where, self._named = f"{locate(n)}: {reasons[0]}", True
            elif n is not None:
                unit = "line" if (lines is not None or "line" in columns) else "row"
                self.first_where = f"{unit} {n}: {reasons[0]}"
            else:
                self.first_where = str(reasons[0])
        self.counts.update(reasons.tolist())
        if self.path is not None:
            self._parts.append({**{k: np.asarray(v) for k, v in columns.items()}, "reason": reasons})

    def add_unreadable(self, read_rejects) -> None:
        """Add the rows a reader could not parse (``Reject(line, reason, raw)`` of
        :meth:`~hpe_cli.io.readers.TableSource.batches_with_rejects`): their line, raw text and reason."""
        if not read_rejects:
            return
        lines = np.array([r.line for r in read_rejects], dtype=np.int64)
        self.add(
            {"row": lines, "raw": np.array([r.raw for r in read_rejects], dtype=object)},
            [r.reason for r in read_rejects],
            lines=lines,
        )

    def add_choice(self, columns: dict, reasons) -> None:
        """Rows dropped by the user's choice (``--exclude``): listed in the file, never an error, not counted."""
        if self.path is not None and len(reasons):
            self._parts.append({**{k: np.asarray(v) for k, v in columns.items()}, "reason": np.asarray(reasons)})

    def first(self) -> str | None:
        return next(iter(self.counts), None)

    def check(self) -> None:
        """Apply :func:`rejects_rule` (raise if rows were rejected without a file, or with ``strict``)."""
        rejects_rule(
            len(self),
            self.first_where,
            has_file=self.path is not None,
            strict=self.strict,
            source=None if self._named else self.source,
        )

    def finish(self):
        """The end of a command: apply the rule (:meth:`check`), then :meth:`write`."""
        self.check()
        return self.write()

    def write(self):
        """Stage the rejects file (None without a path)."""
        if self.path is None:
            return None
        import pandas as pd

        frame = (
            pd.concat([pd.DataFrame(p) for p in self._parts], ignore_index=True)
            if self._parts
            else pd.DataFrame({"reason": pd.Series([], dtype=str)})
        )
        return write_table(frame, self.path, overwrite=self.overwrite)


def _integral(v) -> bool:
    try:
        return float(v) == int(v)
    except (TypeError, ValueError):
        return False


def fail_all_rejected(rejects: "Rejects", message: str):
    """Every row was rejected: raise. With a rejects file (and no ``--strict``) the error is a
    :class:`~hpe_cli.errors.RejectedAllError` that still commits that file, the one output that says why; the
    main outputs are not written. Without one, a plain :class:`~hpe_cli.errors.HpeError`."""

    if rejects.path is None or rejects.strict:
        raise HpeError(message)

    from .transaction import current  # lazy: start-up

    rejects.write()
    txn = current()
    if txn is not None:  # only the rejects file stays staged: the run's transaction commits it, then fails
        keep = realpath(rejects.path)
        for tmp in txn.staged_temps():
            if realpath(txn.target_of(tmp)) != keep:
                txn.discard(tmp)
    raise RejectedAllError(f"{message}; every row's reason -> {rejects.path}", keep=[rejects.path])
