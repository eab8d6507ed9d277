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


class _DeclaredPath(click.Path):
    """A path declared to the run's output transaction as it is parsed (``_declare``: its method name)."""

    _declare = ""

    def convert(self, value, param, ctx):
        value = super().convert(value, param, ctx)
        from ..io.transaction import current

        txn = current()
        if txn is not None:
            getattr(txn, self._declare)(value, _label(param))  # a collision is an HpeError: one line, exit 1
        return value


class InputPath(_DeclaredPath):
    """A path the run reads: declared to the run's output transaction, so no output may resolve to it."""

    _declare = "add_input"


class OutputPath(_DeclaredPath):
    """A path the run writes: declared to the run's output transaction (no collision with inputs/outputs)."""

    _declare = "add_output"


def _label(param) -> str:
    if param is None:
        return ""
    if param.param_type_name == "argument":
        return (param.human_readable_name or "").upper()
    longs = [o for o in param.opts if o.startswith("--")]
    return (longs or param.opts or [""])[0]


def _as(cls, t: click.Path) -> click.Path:
    new = cls.__new__(cls)
    new.__dict__.update(t.__dict__)
    return new


def mark_paths(command):
    """Declare every path parameter of ``command`` as an input or an output of its run.

    Explicit :class:`InputPath`/:class:`OutputPath` types are kept; any other
    ``click.Path`` is an input when it must exist (``exists=True``) and an output
    otherwise. Done once per command object (the group calls it for every command).
    """
    if getattr(command, "_hpe_paths_marked", False):
        return command
    for p in getattr(command, "params", ()):
        t = p.type
        if isinstance(t, (InputPath, OutputPath)) or not isinstance(t, click.Path):
            continue
        p.type = _as(InputPath if t.exists else OutputPath, t)
    command._hpe_paths_marked = True
    return command


def output_option(required: bool = True, help: str = "Output table (.parquet or .csv)."):
    return click.option("-o", "--output", type=OutputPath(dir_okay=False), required=required, help=help)


def system_option(default: str | None = "300w_lp", help: str = "Rotation system of the labels: a built-in name "
                  "(see `hpe systems`) or a .toml file."):
    return click.option("--system", "system", type=SYSTEM, default=default, show_default=True, help=help)


def reinterpret_option(f):
    """``--reinterpret-as SYSTEM``: read the labels in SYSTEM although the file's own metadata names another."""
    return click.option("--reinterpret-as", "reinterpret_as", type=SYSTEM, default=None,
                        help="The file's own system metadata is wrong: read its labels in this system instead "
                             "(an explicit --system/--from that disagrees with the metadata is otherwise an "
                             "error).")(f)


overwrite_option = click.option("--overwrite", is_flag=True, help="Replace OUTPUT if it exists.")
rejects_option = click.option("--rejects", type=OutputPath(dir_okay=False),
                              help="Write rows that could not be used here, with a 'reason' column (without "
                                   "it, any such row makes the command exit 1 and write nothing).")
strict_option = click.option("--strict", is_flag=True,
                             help="Exit 1 and write nothing if any row is rejected (even with --rejects).")


def rejects_options(f):
    """``--rejects FILE`` and ``--strict``: every command that sets rows aside has both."""
    return rejects_option(strict_option(f))
batch_option = click.option("--batch-size", type=click.IntRange(1), default=65_536, show_default=True,
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
    """Print summary lines to stderr unless ``--quiet``; inside a run, once its outputs are committed."""
    if quiet:
        return
    from ..io.system_meta import summary_lines
    from ..io.transaction import current, printable

    lines = [printable(line) for line in list(lines) + summary_lines()]

    def show():
        for line in lines:
            click.echo(line, err=True)

    txn = current()
    if txn is None:
        show()
    else:
        txn.after_commit(show)


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
