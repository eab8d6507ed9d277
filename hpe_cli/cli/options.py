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
            folded = fold_system_name(value, system_names())  # names match case-insensitively
            if folded is not None:
                return get_system(folded)
            self.fail(_unknown_system(value, system_names()), param, ctx)


SYSTEM = SystemType()


class SystemListType(click.ParamType):
    """Comma-separated system names or ``.toml`` files, each as :class:`SystemType` reads it."""

    name = "SYSTEM[,SYSTEM...]"

    def convert(self, value, param, ctx):
        if isinstance(value, (list, tuple)):
            return list(value)
        return [SYSTEM.convert(v.strip(), param, ctx) for v in str(value).split(",") if v.strip()]


SYSTEMS = SystemListType()


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
    from .suggest import suggesting_choices

    suggesting_choices(command)  # every choice option says "did you mean" (``--layout fsa-net`` -> fsanet)
    command._hpe_paths_marked = True
    return command


def output_option(required: bool = True, help: str = "Output table (.parquet or .csv)."):
    return click.option("-o", "--output", type=OutputPath(dir_okay=False), required=required, help=help)


def system_option(
    default: str | None = "300w_lp",
    help: str = "Rotation system of the labels: a built-in name (see `hpe systems`) or a .toml file.",
):
    return click.option("--system", "system", type=SYSTEM, default=default, show_default=True, help=help)


#: the default of ``--system`` for commands that read a labels file that may name its own system
FILE_SYSTEM_DEFAULT = "[default: the file's own (hpe:system metadata, dataset format), else 300w_lp]."


def file_system_option(
    what: str = "Rotation system of the labels: a built-in name (see `hpe systems`) or a .toml file",
):
    """``--system`` of the commands that read one labels file: ``what`` it is, then :data:`FILE_SYSTEM_DEFAULT`."""
    return click.option("--system", "system", type=SYSTEM, default=None, help=f"{what} {FILE_SYSTEM_DEFAULT}")


def output_folder_option(help: str):
    """``-o/--output DIR``: the folder a command writes (created if missing), as the ``outdir`` argument."""
    return click.option("-o", "--output", "outdir", type=click.Path(file_okay=False), required=True, help=help)


def images_option(help: str):
    """``--images DIR``: the folder a table's image paths are relative to, as the ``images`` argument."""
    return click.option("--images", type=click.Path(exists=True, file_okay=False), help=help)


def reinterpret_option(f):
    """``--reinterpret-as SYSTEM``: read the labels in SYSTEM although the file's own metadata names another."""
    return click.option(
        "--reinterpret-as",
        "reinterpret_as",
        type=SYSTEM,
        default=None,
        help="The file's own system metadata is wrong: read its labels in this system instead "
        "(an explicit --system/--from that disagrees with the metadata is otherwise an "
        "error).",
    )(f)


overwrite_option = click.option("--overwrite", is_flag=True, help="Replace OUTPUT if it exists.")
rejects_option = click.option(
    "--rejects",
    type=OutputPath(dir_okay=False),
    help="Write rows that could not be used here, with a 'reason' column (without "
    "it, any such row makes the command exit 1 and write nothing).",
)
strict_option = click.option(
    "--strict", is_flag=True, help="Exit 1 and write nothing if any row is rejected (even with --rejects)."
)


def rejects_options(f):
    """``--rejects FILE`` and ``--strict``: every command that sets rows aside has both."""
    return rejects_option(strict_option(f))


batch_option = click.option(
    "--batch-size", type=click.IntRange(1), default=65_536, show_default=True, help="Rows per streamed batch."
)


def verbosity_options(f):
    f = click.option("-q", "--quiet", is_flag=True, help="No progress bar or summary.")(f)
    f = click.option("-v", "--verbose", count=True, help="More detail on stderr.")(f)
    return f


class QuietProgress:
    """What ``--quiet`` gets instead of a tqdm bar: the calls the commands make, doing nothing (and tqdm, with its
    imports and monitor thread, is not loaded)."""

    disable = True

    def __init__(self, total=None):
        self.total, self.n = total, 0

    def update(self, n=1) -> None:
        self.n += n

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> bool:
        return False

    def __getattr__(self, name):  # close, refresh, set_postfix, set_description, ...: nothing to do
        return lambda *args, **kwargs: None


def progress(total=None, desc: str = "", quiet: bool = False, unit: str = "rows"):
    """A tqdm bar on stderr; off with ``--quiet`` (:class:`QuietProgress`), and when stderr is not a terminal
    (logs, CI)."""
    if quiet:
        return QuietProgress(total)
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        unit_scale=True,
        disable=None,  # off when stderr is not a terminal
        file=sys.stderr,
        dynamic_ncols=True,
        leave=False,
    )


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


#: values below this are at double rounding level (a few ulps of 1): printed as "< 1e-12", never as digits
ROUNDING_LEVEL = 1e-12


def fmt_small(x: float, spec: str = ".3g") -> str:
    """``x`` formatted with ``spec``, or ``"< 1e-12"`` when ``0 <= x < 1e-12``.

    Digits at rounding level depend on the CPU's SIMD paths (``1.12e-15`` on one machine, ``6.57e-16`` on another);
    printing the bound keeps summaries and documented outputs identical across machines.
    """
    x = float(x)
    if 0.0 <= x < ROUNDING_LEVEL:
        return f"< {ROUNDING_LEVEL:g}"
    return format(x, spec)


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


# --------------------------------------------------------------------------------------------------------------
# One spelling per idea (image sizes, angle units, fit thresholds), with the old spellings as warned aliases.


class ImageSize(click.ParamType):
    """``WxH`` in pixels (``1920x1080``), returned as ``(W, H)``; a usage error otherwise."""

    name = "WxH"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        try:
            w, h = (int(v) for v in str(value).lower().replace("×", "x").split("x"))
        except ValueError:
            self.fail(f"expected WIDTHxHEIGHT in pixels such as 1920x1080, got {value!r}", param, ctx)
        if not (1 <= w <= 100_000 and 1 <= h <= 100_000):
            self.fail(f"expected sizes between 1 and 100000 pixels, got {value!r}", param, ctx)
        return (w, h)


IMAGE_SIZE = ImageSize()


def image_size_option(*names, help="Width and height of the images, in pixels, as WxH (e.g. 1920x1080).", **kw):
    """``--image-size WxH``: the one spelling of an image size (``--image-size W H`` is a warned alias)."""
    return click.option("--image-size", *names, type=IMAGE_SIZE, metavar="WxH", help=help, **kw)


RADIANS_HELP = "Angle columns of the input are in radians (default: degrees; hpe always writes degrees)."


#: ``--columns``: which label columns a command reads
COLUMN_KINDS = ("auto", "angles", "matrix")


def columns_option(help: str):
    """``--columns auto|angles|matrix`` (parameter ``use``): which label columns a command reads."""
    return click.option(
        "--columns", "use", type=click.Choice(COLUMN_KINDS), default="auto", show_default=True, help=help
    )


def label_frame_option(f):
    """``--frame camera|crop`` (parameter ``label_frame``) of the relabelling commands."""
    return click.option(
        "--frame",
        "label_frame",
        type=click.Choice(["camera", "crop"]),
        default="camera",
        show_default=True,
        help="camera: labels relative to the camera's optical axis; crop: relative to the line of sight "
        "to the head centre, as a network sees a crop (adds ray_angle). See docs/label_frames.md.",
    )(f)


def label_system_option(whose: str):
    """``--system`` of the relabelling commands (default 300w_lp; whenet for the formats storing ``whose`` angles)."""
    return click.option(
        "--system",
        "system",
        type=SYSTEM,
        default=None,
        help="Rotation system of the labels: built-in name or .toml file "
        f"[default: 300w_lp; whenet for --format coco/whenet, which store {whose} angles].",
    )


_PRESETS = {
    "whenet": "whenet (radius 22, aspect <= 2)",
    "directmhp": "directmhp (radius 18, aspect < 1.5, each side < 70% of the image)",
}


def preset_option(default: str):
    """``--preset whenet|directmhp``: the helmet radius and box rule, ``default`` first."""
    order = [default] + [p for p in _PRESETS if p != default]
    return click.option(
        "--preset",
        type=click.Choice(order),
        default=default,
        show_default=True,
        help=f"Helmet radius and box rule: {_PRESETS[order[0]]} or {_PRESETS[order[1]]}.",
    )


def radians_option(help: str = RADIANS_HELP):
    """``--radians``: the one spelling of input angle units."""
    return click.option("--radians", is_flag=True, help=help)


class Length(click.ParamType):
    """A length with an optional unit suffix (``2cm``, ``0.02m``, ``20mm``; a bare number is in ``default``),
    returned in ``unit``; ``inf`` is accepted (no threshold)."""

    name = "CM"
    _scale = {"mm": 0.1, "cm": 1.0, "m": 100.0}

    def __init__(self, unit: str = "cm", default: str = "cm"):
        self.unit, self.default = unit, default

    def convert(self, value, param, ctx):
        if value is None or isinstance(value, float):
            return value
        import re

        m = re.fullmatch(r"\s*([-+0-9.eE]+|inf|infinity)\s*(mm|cm|m)?\s*", str(value).lower())
        try:
            number = float(m.group(1)) if m else float("nan")
        except ValueError:
            number = float("nan")
        if not number >= 0:
            self.fail(f"expected a length >= 0 such as 2, 2cm, 0.02m or 20mm (or inf), got {value!r}", param, ctx)
        unit = m.group(2) or self.default
        if m.group(2) is None and 0 < number < 0.1 and self.default == "cm":
            _warn(
                f"{value} is read as {number:g} cm ({number * 10:g} mm): this option is in centimetres; "
                f"write {value}m for metres"
            )
        return number * self._scale[unit] / self._scale[self.unit]


def max_rmse_option(unit: str, default_cm: float, note: str):
    """``--max-rmse``: a fit threshold in centimetres everywhere (unit suffixes accepted), given to the command in
    ``unit`` (what its pipeline uses)."""
    return click.option(
        "--max-rmse",
        type=Length(unit=unit),
        default=None,
        metavar="CM",
        help=f"Reject faces whose fit RMSE is above this, in centimetres; a unit suffix is accepted (2cm, 0.02m, "
        f"20mm). 'inf' labels every fit. [default: {default_cm:g} cm: {note}]",
    )


def _warn(msg: str) -> None:
    click.echo(f"Warning: {msg}", err=True)


def _rewrite_deprecated(args, names):
    """Rewrite the deprecated spellings in ``names`` (a subset of image-size, canvas, units) to the current ones."""
    out, i, args = [], 0, list(args)
    while i < len(args):
        a = args[i]
        if a == "--":
            out += args[i:]
            break
        a = str(a)
        if "canvas" in names and (a == "--canvas" or a.startswith("--canvas=")):
            _warn("--canvas is deprecated; use --image-size WxH")
            out.append("--image-size" + a[len("--canvas") :])
        elif (
            "image-size" in names
            and a == "--image-size"
            and i + 2 < len(args)
            and str(args[i + 1]).isdigit()
            and str(args[i + 2]).isdigit()
        ):
            _warn(
                f"--image-size {args[i + 1]} {args[i + 2]} is deprecated; use --image-size {args[i + 1]}x{args[i + 2]}"
            )
            out += ["--image-size", f"{args[i + 1]}x{args[i + 2]}"]
            i += 2
        elif "units" in names and (a == "--units" or a.startswith("--units=")):
            value = a.split("=", 1)[1] if "=" in a else (args[i + 1] if i + 1 < len(args) else "")
            if "=" not in a:
                i += 1
            flag = {"rad": "--radians", "deg": "--degrees"}.get(value)
            if flag is None:
                raise click.UsageError(
                    f"Invalid value for '--units': expected rad or deg, got {value!r} "
                    "(deprecated: use --radians or --degrees)"
                )
            _warn(f"--units {value} is deprecated; use {flag}")
            out.append(flag)
        else:
            out.append(a)
        i += 1
    return out


def deprecated_spellings(*names):
    """Let ``command`` accept old spellings (``image-size``: ``--image-size W H``; ``canvas``: ``--canvas WxH``;
    ``units``: ``--units rad|deg``), each rewritten with a warning on stderr before parsing."""

    def deco(command):
        parse = command.parse_args

        def parse_args(ctx, args):
            return parse(ctx, _rewrite_deprecated(args, names))

        command.parse_args = parse_args
        return command

    return deco


def fold_system_name(value, names):
    """The built-in name equal to ``value`` up to case (``300W_LP`` -> ``300w_lp``), or None."""
    low = str(value).lower()
    return next((n for n in names if n.lower() == low), None)


def _unknown_system(value, names) -> str:
    """'unknown system' with a "did you mean" for near misses (``300wlp``, ``6DRepNet``, ``biwii``)."""
    from .suggest import near_names

    near = near_names(value, names)
    hint = f"did you mean {' or '.join(near)}? " if near else ""
    return f"unknown system {value!r}; {hint}expected one of: {', '.join(names)} or a .toml file"


def known_rows(*paths) -> int | None:
    """Rows of the inputs when known before reading (Parquet metadata, a folder's ``.mat`` files), else None."""
    from pathlib import Path

    total = 0
    for p in map(Path, paths):
        try:
            if p.is_dir():
                n = sum(1 for _ in p.glob("*.mat"))
                if not n:
                    return None
            else:
                with open(p, "rb") as f:
                    if f.read(4) != b"PAR1":
                        return None
                import pyarrow.parquet as pq

                n = pq.ParquetFile(p).metadata.num_rows
        except (OSError, ValueError):
            return None
        total += n
    return total


#: the label-file formats relabel-panoptic and relabel-agora write
OUTPUT_FORMATS = ("table", "coco", "whenet")


def format_option(f):
    """``--format table|coco|whenet`` of the relabel commands (default: from OUTPUT's extension)."""
    return click.option(
        "--format",
        "fmt",
        type=click.Choice(OUTPUT_FORMATS),
        default=None,
        help="table (Parquet/CSV), coco (DirectMHP's COCO JSON) or whenet (annotation.txt lines) "
        "[default: from OUTPUT's extension].",
    )(f)


def exclude_option(f):
    """``--exclude FILE``: drop the rows a key list names (``hpe audit --consistency --suspects`` writes one)."""
    return click.option(
        "--exclude",
        type=click.Path(exists=True, dir_okay=False),
        default=None,
        help="Leave out the rows listed in this key list (.csv/.parquet with key columns such as image, "
        "sequence, frame, camera, person_id and a 'reason', as `hpe audit --consistency --suspects` writes); "
        "they are listed in --rejects with 'excluded: <reason>' and are never an error.",
    )(f)


#: the commands that run units on Dask (relabel-panoptic, export) share these two options' words
SCHEDULER_HELP = (
    "Run the units on a Dask distributed scheduler (tcp://host:8786), or 'local' for a "
    "LocalCluster of --workers processes. Needs the dask extra."
)


def scheduler_option(f):
    """``--scheduler ADDRESS``: the units on a Dask cluster (:mod:`hpe_cli.pipelines.dask_runner`)."""
    return click.option("--scheduler", default=None, metavar="ADDRESS", help=SCHEDULER_HELP)(f)


def resume_option(compared: str):
    """``--resume``: keep the finished units of an interrupted run; ``compared`` says how inputs are compared
    (``"calibration files are compared by their contents, ..."``)."""
    return click.option(
        "--resume",
        is_flag=True,
        help="Keep the finished units of an interrupted run with the same inputs and options "
        "(parts in .OUTPUT.hpe-parts/) and compute only the others; the result is the same bytes. "
        "Give it on the first run too: a run without --resume removes its parts when interrupted. "
        f"A changed input is refused, naming the file: {compared}. The temp files "
        "of the run it resumes (killed by kill -9 or a power cut) are removed.",
    )


#: --threads: the same help on every command that takes it (tests/docs/test_cli_consistency.py)
THREADS_HELP = (
    "Threads that process rows, at least 1 [default: one per core, os.cpu_count(), at most 8]. The output is the "
    "same whatever the number."
)


def threads_option(f):
    """``--threads N``: the threads a command processes rows on (default: one per core)."""
    return click.option("--threads", type=click.IntRange(1), default=None, metavar="N", help=THREADS_HELP)(f)
