"""Reader options of the running command (no numpy/pyarrow import: ``hpe --help`` stays fast).

The CLI's ``--columns-map/--delimiter/--no-header/--names/--input-format``
(:func:`hpe_cli.cli.table_options.column_options`) are held here for the
duration of a command, and every :func:`~hpe_cli.io.readers.open_table` call
that passes no table options of its own uses them.
"""

from __future__ import annotations

import contextvars

_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("hpe_table_options", default=None)


def active_table_options() -> dict | None:
    """The ``open_table`` options of the running command, or None."""
    return _ACTIVE.get()


def set_table_options(opts):
    """Hold ``opts`` (``open_table`` keyword arguments) for the running command; returns a reset token."""
    return _ACTIVE.set(opts)


def reset_table_options(token) -> None:
    _ACTIVE.reset(token)
