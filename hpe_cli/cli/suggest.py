"""Suggestions ("did you mean") for every name a user types: commands, choices of options, systems.

One rule everywhere: names are compared folded (lower case, letters and digits only, so ``fsa-net``, ``FSANet``
and ``fsa_net`` all fold to ``fsanet``), a folded match wins outright, otherwise the close matches of
:func:`difflib.get_close_matches` are offered.
"""

from __future__ import annotations

import click


def fold(name) -> str:
    """``name`` lower-cased with everything but letters and digits removed."""
    return "".join(ch for ch in str(name).lower() if ch.isalnum())


def near_names(value, names, n: int = 3, cutoff: float = 0.75) -> list[str]:
    """The names in ``names`` a user most likely meant by ``value`` (best first; empty if none is close)."""
    import difflib

    keyed: dict[str, str] = {}
    for name in names:
        keyed.setdefault(fold(name), str(name))
    key = fold(value)
    if key in keyed:
        return [keyed[key]]
    close = difflib.get_close_matches(key, list(keyed), n=n, cutoff=cutoff)
    if not close:  # a prefix of one name only (``conv`` -> ``convert``)
        close = [k for k in keyed if key and k.startswith(key)][:1] if len(key) >= 3 else []
    return [keyed[k] for k in close]


def did_you_mean(value, names) -> str:
    """``" (did you mean 'x'?)"`` or ``" (did you mean 'x' or 'y'?)"``, or ``""`` when nothing is close."""
    near = near_names(value, names)
    return f" (did you mean {' or '.join(repr(n) for n in near)}?)" if near else ""


class SuggestChoice(click.Choice):
    """A :class:`click.Choice` whose error names the choice the user most likely meant (``fsa-net`` -> ``fsanet``).

    The command group turns every ``click.Choice`` of every command into this type (:func:`suggesting_choices`),
    so no command has to ask for it.
    """

    def convert(self, value, param, ctx):
        try:
            return super().convert(value, param, ctx)
        except click.BadParameter as exc:
            hint = did_you_mean(value, self.choices)
            if not hint:
                raise
            self.fail(f"{exc.message.rstrip('.')}{hint}.", param, ctx)


def suggesting_choices(command) -> None:
    """Make every ``click.Choice`` parameter of ``command`` a :class:`SuggestChoice` (same choices, same flags)."""
    for p in getattr(command, "params", ()):
        t = p.type
        if isinstance(t, click.Choice) and not isinstance(t, SuggestChoice):
            new = SuggestChoice.__new__(SuggestChoice)
            new.__dict__.update(t.__dict__)
            p.type = new
