"""Options fields renamed to the spelling the other commands' options share (``threads``, ``rejects``, ``strict``,
as ``--threads``, ``--rejects``, ``--strict``): the old keyword still works, with a ``DeprecationWarning``."""

from __future__ import annotations

import dataclasses
import warnings

from ..errors import UsageError


def take_renamed(options, old: str, new: str) -> None:
    """In a frozen options dataclass's ``__post_init__``: move ``old`` (given by a caller of the old spelling) to
    ``new``, warning once; ``old`` is left None, so ``dataclasses.replace`` does not warn again.

    Raises
    ------
    UsageError
        Both spellings given, with different values: "expected one of old, new, got both".
    """
    value = getattr(options, old)
    if value is None:
        return
    warnings.warn(f"{type(options).__name__}: {old}= is deprecated, use {new}=", DeprecationWarning, stacklevel=4)
    default = next(f.default for f in dataclasses.fields(options) if f.name == new)
    current = getattr(options, new)
    if current != default and current != value:
        raise UsageError(f"{old}, {new}: expected one of them, got both ({value!r} and {current!r})")
    object.__setattr__(options, new, value)
    object.__setattr__(options, old, None)
