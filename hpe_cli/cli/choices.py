"""Choices read from a registry on first use, so declaring an option imports no table.

``--layout``, ``--protocol``, ``--decoder``, ``--input-format``, ``--format`` and the like list the names of one
:class:`hpe_cli.registry.Registry`. The option is declared when its click module is imported (``hpe --help``
imports every command module), but the registry -- and the modules that fill it -- is only imported when the
choices are first needed: parsing a value, ``hpe CMD --help``, shell completion.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from .suggest import SuggestChoice


class RegistryChoice(SuggestChoice):
    """A :class:`click.Choice` (with "did you mean") whose names come from a registry, looked up lazily.

    Parameters
    ----------
    table : str
        ``"module:NAME"`` of the :class:`~hpe_cli.registry.Registry` (or of a function returning names).
    extra : tuple of str
        Names accepted besides the table's, after them (``all``).
    first : tuple of str
        Names accepted besides the table's, before them (``auto``).
    keep : callable, optional
        ``keep(entry) -> bool``: only the entries it keeps (e.g. decoders of one kind).
    attribute : str, optional
        List this attribute of the entries (a tuple each, merged in order, duplicates once) instead of the names.
    """

    def __init__(
        self,
        table: str,
        extra: tuple = (),
        *,
        first: tuple = (),
        keep: Callable | None = None,
        attribute: str | None = None,
        case_sensitive: bool = True,
    ):
        self.table = table
        self.extra = tuple(extra)
        self.first = tuple(first)
        self.keep = keep
        self.attribute = attribute
        self.case_sensitive = case_sensitive

    @property
    def choices(self) -> tuple:
        # read on every use (cheap): an entry registered after the option was first shown is accepted too
        module, name = self.table.split(":")
        table = getattr(importlib.import_module(module), name)
        table = table() if callable(table) and not hasattr(table, "names") else table
        if self.attribute is not None:
            names = dict.fromkeys(v for entry in table.values() for v in getattr(entry, self.attribute))
        elif self.keep is not None:
            names = table.filter(self.keep)
        else:
            names = table.names() if hasattr(table, "names") else tuple(table)
        return self.first + tuple(names) + self.extra

    @choices.setter
    def choices(self, value) -> None:  # click.Choice.__init__ and copies set it; the registry decides
        pass
