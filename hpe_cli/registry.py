"""One table per extension point: a decorator registers, the table lists, every caller reads the table.

Like torchvision's ``register_model`` / ``list_models`` / ``get_model``: dataset readers, export layouts,
evaluation protocols, decoders, image layouts and built-in systems each keep one :class:`Registry`. The CLI's
choices and ``--help`` lists, the docs tables and the dispatch all read it, so adding an entry is one new file
with one decorated definition (see the "Extending hpe" page of the docs).

This module is the floor of the layer table (like ``errors``): every layer may import it, it imports nothing of
``hpe_cli``.
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Callable, Iterator, Mapping

_MISSING = object()


class Registry(Mapping):
    """A name -> entry table filled by :meth:`register`.

    Parameters
    ----------
    what : str
        What an entry is, for messages ("export layout", "protocol"...).
    loader : str, optional
        A module imported the first time the table is read: the module that registers the built-in entries, so a
        caller that reads the table never sees it half filled, and importing the registry stays cheap.
    """

    def __init__(self, what: str, *, loader: str | None = None):
        self.what = what
        self._loader = loader
        self._entries: dict = {}

    def _load(self) -> None:
        if self._loader is not None:
            loader, self._loader = self._loader, None
            importlib.import_module(loader)

    def register(self, name: str | None = None, obj=None, *, replace: bool = False):
        """Register ``obj`` under ``name``; without ``obj``, a decorator doing so.

        ``name`` defaults to the entry's ``name`` attribute (or its ``__name__``). Registering a name twice is an
        error unless ``replace=True``.
        """

        def add(entry):
            key = name if name is not None else getattr(entry, "name", None) or entry.__name__
            if not isinstance(key, str) or not key:
                raise ValueError(f"{self.what}: expected a non-empty name, got {key!r}")
            if key in self._entries and not replace and self._entries[key] is not entry:
                raise ValueError(f"{self.what} {key!r} is already registered")
            self._entries[key] = entry
            return entry

        return add if obj is None else add(obj)

    def unregister(self, name: str) -> None:
        """Remove ``name`` (a plug-in undone, or a test's dummy)."""
        self._load()
        self._entries.pop(name, None)

    @contextlib.contextmanager
    def registered(self, name: str, obj) -> Iterator:
        """Register ``obj`` for the duration of a ``with`` block (tests, temporary plug-ins)."""
        self._load()
        before = self._entries.get(name)
        self.register(name, obj, replace=True)
        try:
            yield obj
        finally:
            if before is None:
                self._entries.pop(name, None)
            else:
                self._entries[name] = before

    def get(self, name: str, default=_MISSING):
        """The entry called ``name``; else ``default`` when given, else ``ValueError`` "expected a X among a, b,
        got 'y'"."""
        self._load()
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            if default is not _MISSING:
                return default
            raise ValueError(f"expected a {self.what} among {', '.join(self._entries)}, got {name!r}") from None

    def names(self) -> tuple:
        """Registered names, in registration order."""
        self._load()
        return tuple(self._entries)

    def filter(self, keep: Callable) -> tuple:
        """Names whose entry satisfies ``keep(entry)``."""
        return tuple(n for n, e in list(self.items()) if keep(e))

    def __contains__(self, name) -> bool:
        self._load()
        return name in self._entries

    def __getitem__(self, name):
        self._load()
        return self._entries[name]

    def __iter__(self):
        return iter(self.names())

    def __len__(self) -> int:
        self._load()
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.what!r}: {', '.join(self.names())})"
