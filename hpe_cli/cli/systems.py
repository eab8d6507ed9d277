"""``hpe systems``: list the rotation systems."""

from __future__ import annotations

import click


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("extra", nargs=-1, type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print every system's full definition as JSON.")
@click.option(
    "-v",
    "--verbose",
    is_flag=True,
    help="Also show each system's source (the code or document it follows), its storage kind and "
    "columns, its frame in words (and whether it is left-handed) and how it was verified.",
)
def systems(extra, as_json, verbose):
    """List the built-in rotation systems (and any EXTRA .toml files).

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
        if verbose:
            click.echo(f"  source   {s.source or '(none given)'}")
            click.echo(f"  verified {s.verified or '(not stated)'}")
            for n, e in enumerate(s.examples):
                what = f"angles {e['angles']}" if "angles" in e else f"300W-LP angles {e['canonical_angles']}"
                to = f"values {e['values']}" if "values" in e else f"matrix {e.get('matrix')}"
                click.echo(f"  example  {what} -> {to}")
        click.echo("")
