"""``hpe evaluate``: score head-pose predictions against ground truth, every published protocol by name."""

from __future__ import annotations

import click

from .choices import RegistryChoice
from .options import (
    COLUMN_KINDS,
    SYSTEM,
    batch_option,
    columns_option,
    echo_summary,
    output_option,
    overwrite_option,
    progress,
    radians_option,
    rejects_options,
    threads_option,
    verbosity_options,
)
from .table_options import column_options


def _protocol_help() -> str:
    """One line per protocol with its source (repo@commit file:lines), from the protocol table itself."""
    from ..metrics.protocols import PROTOCOLS

    lines = ["\b", "Protocols (--protocol NAME; each follows its peer's current code, source named):"]
    for p in PROTOCOLS.values():
        lines.append(f"  {p.name:<17}{p.formula}; filter: {p.filter}")
        lines.append(f"  {'':<17}source: {p.source}")
    return "\n    ".join(lines)


def _split_keys(ctx, param, value):
    out = []
    for v in value or ():
        out += [k.strip() for k in v.split(",") if k.strip()]
    return tuple(dict.fromkeys(out))


class _EvaluateCommand(click.Command):
    """``hpe evaluate``: its help lists the protocol table, read when the help is shown (not at import)."""

    _short = False  # inside get_short_help_str: the first sentence needs no protocol table

    @property
    def help(self):
        if not self._short and self._help and "{protocols}" in self._help:
            self._help = self._help.replace("{protocols}", _protocol_help())
        return self._help

    @help.setter
    def help(self, value):
        self._help = value

    def get_short_help_str(self, limit: int = 45) -> str:
        """The first sentence, without reading the protocol table (``hpe --help`` stays light)."""
        self._short = True
        try:
            return super().get_short_help_str(limit)
        finally:
            self._short = False


@click.command(cls=_EvaluateCommand, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 110})
@click.argument("pred", type=click.Path(exists=True))
@click.argument("gt", type=click.Path(exists=True))
@output_option(
    required=False,
    help="Per-pair errors (.parquet or .csv): key columns, gt_/pred_ pitch,yaw,roll "
    "in the GT system (Parquet metadata hpe:system), err_pitch/yaw/roll (wrapped), "
    "geodesic, maev_left/down/front (degrees), frobenius (unitless), "
    "pred_rotation_distance (--orthonormalize), image_path (when images are found).",
)
@click.option(
    "--pred-system",
    type=SYSTEM,
    default=None,
    help="Rotation system of PRED (name or .toml) [default: the file's own; required for files that name none].",
)
@click.option(
    "--gt-system",
    type=SYSTEM,
    default=None,
    help="Rotation system of GT (name or .toml) [default: the file's own; required for files that name none].",
)
@click.option(
    "--key",
    "keys",
    multiple=True,
    callback=_split_keys,
    metavar="COL[,COL...]",
    help="Join columns (default: 'image' if both tables have it, else 'file', else row order).",
)
@click.option(
    "--join",
    "join_mode",
    type=click.Choice(["key", "order"]),
    default="key",
    show_default=True,
    help="key: pair rows by --key columns only; order: pair by position (needs equal row counts).",
)
@click.option(
    "--protocol",
    "protocols",
    multiple=True,
    type=RegistryChoice("hpe_cli.metrics.protocols:PROTOCOLS", extra=("all",)),
    help="Published protocol to reproduce (repeatable; default: all). Each runs its peer's own decomposition: "
    "all of them take about 4x the time of one, so on large files name the ones you report.",
)
@click.option(
    "--align",
    type=click.Choice(["none", "mean"]),
    default="none",
    show_default=True,
    help="mean: remove hpe's chordal-mean rotation offset over all pairs first (not opal23's "
    "alignment: that is --protocol opal23-align, a Karcher mean without rows > 90 deg off).",
)
@click.option(
    "--orthonormalize",
    is_flag=True,
    help="Replace prediction matrices/vectors that are not rotations by the nearest rotation (SVD, "
    "det +1); the distance goes to the per-row output. Off: such rows are rejected.",
)
@click.option(
    "--report",
    "html",
    type=click.Path(dir_okay=False),
    help="Write an HTML page: protocols with sources, --by and --yaw-bins tables, counts, worst rows.",
)
@click.option(
    "--worst",
    type=click.IntRange(min=0),
    default=12,
    show_default=True,
    help="Rows shown in the report's worst-rows table (largest geodesic error).",
)
@click.option(
    "--images",
    type=click.Path(file_okay=False, exists=True),
    help="Folder with the GT images (default: the GT folder when it holds .mat + .jpg).",
)
@click.option("--by", metavar="COL", help="Also report every metric per value of this column.")
@click.option(
    "--yaw-bins",
    type=click.FloatRange(min=0, min_open=True),
    metavar="DEG",
    help="Also report every metric per GT-yaw bin of this width [default with --report: 30, so the page always "
    "has its yaw table].",
)
@click.option(
    "--json",
    "report",
    type=click.Path(dir_okay=False, allow_dash=True),
    help="Write the report as JSON; '-' prints it (the table then goes to stderr).",
)
@click.option(
    "--plots",
    type=click.Path(file_okay=False),
    help="Folder for error-vs-yaw, geodesic CDF and error histogram PNGs plus index.html. Drawn from "
    "every pair up to 400,000 pairs, else from every k-th pair (the figures say which); the "
    "numbers always use all pairs.",
)
@rejects_options
@columns_option("Read pitch,yaw,roll or r00..r22 from both tables (auto: angles if present).")
@click.option("--pred-columns", type=click.Choice(COLUMN_KINDS), help="Override --columns for PRED.")
@click.option("--gt-columns", type=click.Choice(COLUMN_KINDS), help="Override --columns for GT.")
@radians_option()
@overwrite_option
@batch_option
@threads_option
@verbosity_options
@column_options
def evaluate(
    pred,
    gt,
    output,
    pred_system,
    gt_system,
    keys,
    join_mode,
    protocols,
    align,
    orthonormalize,
    html,
    worst,
    images,
    by,
    yaw_bins,
    report,
    plots,
    rejects,
    use,
    pred_columns,
    gt_columns,
    radians,
    overwrite,
    batch_size,
    threads,
    verbose,
    quiet,
    strict,
):
    """Score predictions PRED against ground truth GT, each in its own system.

    PRED and GT are any tables hpe reads (.parquet, .csv, a folder of .mat
    files, BIWI files), holding angles (pitch,yaw,roll) or matrices (r00..r22).
    Every rotation is brought to one frame through its matrix, so the two
    sides may use different conventions. Rows are joined on --key only
    (default 'image', else 'file'; a .mat folder's key is the file stem, and
    names that differ only in folder or extension join on their stem); row
    order is used only with --join order and equal row counts. A GT row
    without a prediction is 'missing', a row that is not a rotation (NaN, not
    orthonormal, det -1) is 'invalid', a prediction without a GT row is
    'unmatched': all are counted and written to --rejects with their file,
    line and reason (without --rejects any of them is an error, exit 1, as
    in every hpe command). Duplicate keys are an error.

    \b
    Metrics (every run; degrees):
      geodesic         angle of P G^T: mean, median, p90, p95, max, within 5/10/15/30
      maev             angle between matching axes (columns) of P and G: left, down, front
      frobenius        ||I - P G^T||_F
      mae_wrapped      per-angle |d| in the GT system, wrapped into [0, 180]
      mae_best_of_two  as mae_wrapped, with the prediction's better Euler solution (opal23)

    {protocols}

    Raw-angle protocols compare the angles as written in the file when they
    mean the same rotation in the protocol's system; rows that had to be
    converted are counted per protocol (re_expressed).

    \b
    Examples:
      hpe evaluate preds.csv AFLW2000/ --pred-system 6drepnet --gt-system 300w_lp
      hpe evaluate preds.parquet gt.parquet --pred-system whenet --gt-system whenet \\
          --protocol directmhp --protocol whenet -o errors.parquet --json report.json
      hpe evaluate preds.csv gt.csv --pred-system opencv --gt-system biwi --key image,person_id \\
          --align mean --by sequence --yaw-bins 15 --plots eval_plots/ --rejects rejects.csv
      hpe evaluate preds.csv gt.csv --pred-system 6drepnet --gt-system 300w_lp --columns matrix --json -
      hpe evaluate trinet_raw.csv gt.csv --pred-system trinet --gt-system 300w_lp --orthonormalize -o rows.parquet
      hpe evaluate preds.csv AFLW2000/ --pred-system 300w_lp --gt-system 300w_lp --report page.html --worst 20
      hpe evaluate preds_in_gt_order.csv gt.csv --pred-system 300w_lp --gt-system 300w_lp --join order
    """
    from ..pipelines.evaluate import EvaluateOptions, JoinUsageError, run_evaluate

    protos = None if (not protocols or "all" in protocols) else list(protocols)
    from .options import known_rows

    if html and yaw_bins is None:  # the page always has its yaw-bin table
        yaw_bins = REPORT_YAW_BINS
    options = EvaluateOptions(
        pred_system=pred_system,
        gt_system=gt_system,
        output=output,
        keys=keys,
        protocols=protos,
        align=align,
        by=by,
        yaw_bins=yaw_bins,
        report=report,
        plots=plots,
        rejects=rejects,
        html=html,
        use_pred=pred_columns or use,
        use_gt=gt_columns or use,
        radians=radians,
        overwrite=overwrite,
        strict=strict,
        batch_size=batch_size,
        join_mode=join_mode,
        orthonormalize=orthonormalize,
        worst=worst,
        images=images,
        threads=threads,
    )
    bar = progress(total=known_rows(pred, gt), desc="evaluate", quiet=quiet)  # both tables' rows, when known
    try:
        result = run_evaluate(pred, gt, options, progress=bar)
    except JoinUsageError as exc:
        raise click.UsageError(str(exc)) from None
    finally:
        bar.close()
    if not quiet:
        lines = format_table(result, verbose)
        to_err = report == "-"
        for line in lines:
            click.echo(line, err=to_err)
    outs = [str(p) for p in (report if report != "-" else None, output, rejects, plots, html) if p]
    if outs:
        echo_summary(["wrote " + ", ".join(outs)], quiet)


#: --yaw-bins of a --report run that names none (degrees)
REPORT_YAW_BINS = 30.0


def format_table(result: dict, verbose: bool = False) -> list:
    """The readable summary (see :func:`hpe_cli.report.evaluate_text.summary_lines`)."""
    from ..report.evaluate_text import summary_lines

    return summary_lines(result, verbose)
