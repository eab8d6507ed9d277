"""Options shared by every command, defined once so names stay consistent."""
from __future__ import annotations

import sys

import click


class SystemType(click.ParamType):
    """A built-in system name or a ``.toml`` file; an unknown name is a usage error (exit 2)."""

    name = "SYSTEM"

    def convert(self, value, param, ctx):
        from ..rotation.systems import RotationSystem, SystemError_, get_system, system_names

        if isinstance(value, RotationSystem):
            return value
        try:
            return get_system(value)
        except SystemError_ as exc:
            if str(value).endswith(".toml"):
                self.fail(str(exc), param, ctx)
            self.fail(f"unknown system {value!r}; expected one of: {', '.join(system_names())} "
                      "or a .toml file", param, ctx)


SYSTEM = SystemType()


def output_option(required: bool = True, help: str = "Output table (.parquet or .csv)."):
    return click.option("-o", "--output", type=click.Path(dir_okay=False), required=required, help=help)


def system_option(default: str | None = "300w_lp", help: str = "Rotation system of the labels: a built-in name "
                  "(see `hpe systems`) or a .toml file."):
    return click.option("--system", "system", type=SYSTEM, default=default, show_default=True, help=help)


overwrite_option = click.option("--overwrite", is_flag=True, help="Replace OUTPUT if it exists.")
rejects_option = click.option("--rejects", type=click.Path(dir_okay=False),
                              help="Write rows that could not be used here, with a 'reason' column.")
batch_option = click.option("--batch-size", type=click.IntRange(1), default=262_144, show_default=True,
                            help="Rows per streamed batch.")


def verbosity_options(f):
    f = click.option("-q", "--quiet", is_flag=True, help="No progress bar or summary.")(f)
    f = click.option("-v", "--verbose", count=True, help="More detail on stderr.")(f)
    return f


def progress(total=None, desc: str = "", quiet: bool = False, unit: str = "rows"):
    """A tqdm bar on stderr; off with ``--quiet``, and when stderr is not a terminal (logs, CI)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, unit_scale=True, disable=True if quiet else None, file=sys.stderr,
                dynamic_ncols=True, leave=False)


def echo_summary(lines, quiet: bool = False) -> None:
    """Print summary lines to stderr unless ``--quiet``."""
    if not quiet:
        for line in lines:
            click.echo(line, err=True)


def format_from_suffix(path) -> str:
    """Relabel output format implied by OUTPUT's name: .json -> coco, .txt -> whenet, else a table."""
    s = str(path).lower()
    if s.endswith(".json"):
        return "coco"
    if s.endswith(".txt"):
        return "whenet"
    return "table"


def non_negative_or_inf(ctx, param, value):
    """Click callback: a threshold that must be >= 0 (``inf`` turns it off)."""
    if value is None:
        return None
    if value != value or value < 0:  # NaN or negative
        raise click.BadParameter(f"expected a number >= 0 or inf, got {value}")
    return value
