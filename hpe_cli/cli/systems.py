"""``hpe systems``: list the rotation systems."""

from __future__ import annotations

import click


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("extra", nargs=-1, metavar="[NAME|FILE.toml]...")
@click.option("--json", "as_json", is_flag=True, help="Print every system's full definition as JSON.")
@click.option(
    "-v",
    "--verbose",
    is_flag=True,
    help="Also show each system's source (the code or document it follows), its storage kind and "
    "columns, its frame in words (and whether it is left-handed) and how it was verified.",
)
def systems(extra, as_json, verbose):
    """List the built-in rotation systems (and any FILE.toml), or only the NAMEd ones.

    Each system is shown with its four defining parts: frame, axes and
    handedness, range (with the primary-solution rule) and order (sequence
    and storage), in words; --json gives the same as data. --verbose adds
    where each definition comes from and whether it was verified on real data.

    \b
    Examples:
      hpe systems
      hpe systems --verbose
      hpe systems --json > systems.json
      hpe systems my_system.toml
      hpe systems 6drepnet whenet
    """
    import json

    from ..rotation.systems import builtin_systems, load_system

    found = _selected(extra, builtin_systems(), load_system)
    if as_json:
        click.echo(json.dumps([{**s.to_dict(), "in_words": s.describe()} for s in found], indent=2))
        return
    for s in found:
        click.secho(s.name, bold=True)
        click.echo(f"  {s.description}")
        for key, text in s.describe().items():
            click.echo(f"  {key:<8} {text}")
        if s.notes:
            click.echo(f"  notes    {s.notes}")
        if verbose:
            click.echo(f"  source   {s.source or '(none given)'}")
            click.echo(f"  verified {s.verified or '(not stated)'}")
            for n, e in enumerate(s.examples):
                what = f"angles {e['angles']}" if "angles" in e else f"300W-LP angles {e['canonical_angles']}"
                to = f"values {e['values']}" if "values" in e else f"matrix {e.get('matrix')}"
                click.echo(f"  example  {what} -> {to}")
        click.echo("")


def _selected(extra, builtins: dict, load_system) -> list:
    """Every built-in plus the given .toml files; with built-in names given, only those (and the files)."""
    from pathlib import Path

    from ..io.transaction import note_input
    from .options import fold_system_name
    from .suggest import did_you_mean

    names, files = [], []
    for item in extra:
        if Path(item).is_file():
            note_input(item)
            files.append(load_system(item))
            continue
        name = fold_system_name(item, list(builtins))
        if name is None:
            kind = "file" if str(item).endswith(".toml") or "/" in str(item) else "built-in system"
            raise click.BadParameter(
                f"no {kind} {item!r}{did_you_mean(item, list(builtins))}; expected a built-in name "
                f"({', '.join(builtins)}) or a .toml file",
                param_hint="NAME|FILE.toml",
            )
        names.append(builtins[name])
    return (names or list(builtins.values())) + files
