"""``column_options``: the --columns-map/--delimiter/--no-header/--names/--input-format options of every command
that reads a table (see :mod:`hpe_cli.io.columns`). No numpy or pyarrow import here: `hpe --help` stays fast."""

from __future__ import annotations

import functools

import click

from ..io.run_options import active_table_options, reset_table_options, set_table_options
from .choices import RegistryChoice


def _split_names(ctx, param, value):
    if value is None:
        return None
    names = [v.strip() for v in value.split(",")]
    if not all(names):
        raise click.BadParameter(f"expected comma-separated names such as image,yaw,pitch,roll, got {value!r}")
    if len(set(names)) != len(names):
        raise click.BadParameter(f"expected distinct names, got {value!r}")
    return names


def _delimiter(ctx, param, value):
    if value is None:
        return None
    v = {"\\t": "\t", "tab": "\t", "space": " ", "semicolon": ";", "comma": ","}.get(value, value)
    if len(v) != 1 or v in '\r\n"':
        raise click.BadParameter(f"expected one character such as ';' or '\\t' (or tab, space), got {value!r}")
    return v


def _columns_map(ctx, param, value):
    if value is None:
        return None
    from ..errors import HpeError
    from ..io.columns import parse_columns_map

    try:
        parse_columns_map(value)
    except HpeError as exc:
        raise click.BadParameter(str(exc).replace("--columns-map: ", "")) from None
    return value


def column_options(f):
    """Click decorator adding ``--columns-map``, ``--delimiter``, ``--no-header``, ``--names``, ``--input-format``
    and ``--reinterpret-as`` (:func:`hpe_cli.cli.options.reinterpret_option`).

    The command function never sees these values: they are held for the
    duration of the command and every :func:`~hpe_cli.io.readers.open_table`
    call that passes no table options of its own uses them, so adding this
    one decorator is all a command needs.
    """

    @functools.wraps(f)
    def wrapper(*args, **kwargs):
        from ..io.system_meta import reset_reinterpret, set_reinterpret

        opts = pop_table_kwargs(kwargs)
        given = any(v not in (None, True) for v in opts.values())
        token = set_table_options(opts if given else None)
        rtoken = set_reinterpret(kwargs.pop("reinterpret_as", None))
        try:
            if opts["columns"]:
                _check_columns_map(opts["columns"], kwargs)
            return f(*args, **kwargs)
        finally:
            reset_reinterpret(rtoken)
            reset_table_options(token)

    from .options import reinterpret_option

    g = reinterpret_option(wrapper)
    g = click.option(
        "--input-format",
        type=RegistryChoice("hpe_cli.io.dataset_readers:input_format_names"),
        default=None,
        help="Read INPUT as a named label list: whenet (annotation.txt), opal23, img2pose-biwi, "
        "celeba-pose (CelebAMask-HQ-pose-anno.txt) or coco (DirectMHP JSON). "
        "COCO .json and annotation.txt are recognised without it.",
    )(g)
    g = click.option(
        "--names",
        callback=_split_names,
        metavar="A,B,...",
        help="Column names of a headerless file, in order (with --no-header).",
    )(g)
    g = click.option("--no-header", is_flag=True, help="INPUT has no header line (name columns with --names).")(g)
    g = click.option(
        "--delimiter",
        callback=_delimiter,
        metavar="CHAR",
        help="Field delimiter of a text INPUT (e.g. ';', tab, space); any file suffix.",
    )(g)
    g = click.option(
        "--columns-map",
        "columns_map",
        callback=_columns_map,
        metavar="NAME=SOURCE,...",
        help="Rename INPUT columns to hpe's names, e.g. pitch=Pitch,yaw=Yaw,roll=Roll "
        "(also r00..r22, rx,ry,rz, qw..qz, image, bbox_x.., person, ...).",
    )(g)
    return g


#: command arguments that name input tables
_INPUT_ARGS = ("input", "pred", "gt", "labels", "data")


def _check_columns_map(columns, kwargs):
    """Before any work: every source column of ``--columns-map`` must be in at least one input table."""
    from pathlib import Path

    from ..errors import HpeError
    from ..io.columns import parse_columns_map
    from ..io.readers import open_table

    paths = []
    for name in _INPUT_ARGS:
        v = kwargs.get(name)
        for p in v if isinstance(v, (list, tuple)) else [v]:
            if isinstance(p, (str, Path)) and Path(p).exists():
                paths.append(p)
    if not paths:
        return
    found = set()
    token = set_table_options({**active_table_options(), "columns": None})  # the inputs' own names
    try:
        for p in paths:
            found |= set(open_table(p).columns)
    finally:
        reset_table_options(token)
    mapping = parse_columns_map(columns)
    missing = [s for s in mapping if s not in found]
    if missing:
        raise HpeError(
            f"{paths[0]}: --columns-map names column(s) {', '.join(map(repr, missing))} that no input "
            f"has; found {', '.join(sorted(found))[:300]}"
        )


def table_kwargs(columns_map=None, delimiter=None, no_header=False, names=None, input_format=None) -> dict:
    """``open_table`` keyword arguments from :func:`column_options` values."""
    return {
        "columns": columns_map,
        "delimiter": delimiter,
        "header": not no_header,
        "names": names,
        "input_format": input_format,
    }


def pop_table_kwargs(kwargs: dict) -> dict:
    """Remove the :func:`column_options` values from a command's kwargs and return ``open_table`` kwargs."""
    return table_kwargs(
        kwargs.pop("columns_map", None),
        kwargs.pop("delimiter", None),
        kwargs.pop("no_header", False),
        kwargs.pop("names", None),
        kwargs.pop("input_format", None),
    )
