"""``hpe systems``: list the rotation systems."""
from __future__ import annotations

import click


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("extra", nargs=-1, type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print every system's full definition as JSON.")
def systems(extra, as_json):
    """List the built-in rotation systems (and any EXTRA .toml files).

    Each system is shown with its four defining parts: frame, axes and
    handedness, range (with the primary-solution rule) and order (sequence
    and storage), in words; --json gives the same as data.

    \b
    Examples:
      hpe systems
      hpe systems --json > systems.json
      hpe systems my_system.toml
    """
    import json

    from ..rotation.systems import builtin_systems, load_system

    found = list(builtin_systems().values()) + [load_system(p) for p in extra]
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
        click.echo("")
