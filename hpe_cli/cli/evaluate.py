"""``hpe evaluate``: score head-pose predictions against ground truth, every published protocol by name."""
from __future__ import annotations

import click

from .table_options import column_options

from .options import SYSTEM, batch_option, echo_summary, output_option, overwrite_option, progress, \
    rejects_options, verbosity_options

_PROTOCOL_NAMES = ("hopenet", "fsanet", "6drepnet", "6drepnet360", "6drepnet360-2023", "directmhp",
                   "directmhp-single", "whenet", "opal23", "opal23-align", "headposeplus", "img2pose", "trinet",
                   "opentrack", "dad3dheads")


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


@click.command(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 110})
@click.argument("pred", type=click.Path(exists=True))
@click.argument("gt", type=click.Path(exists=True))
@output_option(required=False, help="Per-pair errors (.parquet or .csv): key columns, gt_/pred_ pitch,yaw,roll "
                                    "in the GT system, err_pitch/yaw/roll (wrapped), geodesic, maev_left/down/"
                                    "front, frobenius.")
@click.option("--pred-system", type=SYSTEM, required=True, help="Rotation system of PRED (name or .toml).")
@click.option("--gt-system", type=SYSTEM, required=True, help="Rotation system of GT (name or .toml).")
@click.option("--key", "keys", multiple=True, callback=_split_keys, metavar="COL[,COL...]",
              help="Join columns (default: 'image' if both tables have it, else 'file', else row order).")
@click.option("--join", "join_mode", type=click.Choice(["key", "order"]), default="key", show_default=True,
              help="key: pair rows by --key columns only; order: pair by position (needs equal row counts).")
@click.option("--protocol", "protocols", multiple=True, type=click.Choice(_PROTOCOL_NAMES + ("all",)),
              help="Published protocol to reproduce (repeatable; default: all).")
@click.option("--align", type=click.Choice(["none", "mean"]), default="none", show_default=True,
              help="mean: remove hpe's chordal-mean rotation offset over all pairs first (not opal23's "
                   "alignment: that is --protocol opal23-align, a Karcher mean without rows > 90 deg off).")
@click.option("--orthonormalize", is_flag=True,
              help="Replace prediction matrices/vectors that are not rotations by the nearest rotation (SVD, "
                   "det +1); the distance goes to the per-row output. Off: such rows are rejected.")
@click.option("--report", "html", type=click.Path(dir_okay=False),
              help="Write an HTML page: protocols with sources, --by and --yaw-bins tables, counts, worst rows.")
@click.option("--worst", type=click.IntRange(min=0), default=12, show_default=True,
              help="Rows shown in the report's worst-rows table (largest geodesic error).")
@click.option("--images", type=click.Path(file_okay=False, exists=True),
              help="Folder with the GT images (default: the GT folder when it holds .mat + .jpg).")
@click.option("--by", metavar="COL", help="Also report every metric per value of this column.")
@click.option("--yaw-bins", type=click.FloatRange(min=0, min_open=True), metavar="DEG",
              help="Also report every metric per GT-yaw bin of this width.")
@click.option("--json", "report", type=click.Path(dir_okay=False, allow_dash=True),
              help="Write the report as JSON; '-' prints it (the table then goes to stderr).")
@click.option("--plots", type=click.Path(file_okay=False),
              help="Folder for error-vs-yaw, geodesic CDF and error histogram PNGs plus index.html.")
@rejects_options
@click.option("--columns", "use", type=click.Choice(["auto", "angles", "matrix"]), default="auto",
              show_default=True, help="Read pitch,yaw,roll or r00..r22 from both tables (auto: angles if present).")
@click.option("--pred-columns", type=click.Choice(["auto", "angles", "matrix"]), help="Override --columns for PRED.")
@click.option("--gt-columns", type=click.Choice(["auto", "angles", "matrix"]), help="Override --columns for GT.")
@click.option("--radians", is_flag=True, help="Angle columns of both tables are in radians.")
@overwrite_option
@batch_option
@verbosity_options
@column_options
def evaluate(pred, gt, output, pred_system, gt_system, keys, join_mode, protocols, align, orthonormalize, html, worst,
             images, by, yaw_bins, report, plots, rejects, use, pred_columns, gt_columns, radians, overwrite,
             batch_size, verbose, quiet, strict):
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
    """
    from ..pipelines.evaluate import JoinUsageError, run_evaluate

    protos = None if (not protocols or "all" in protocols) else list(protocols)
    bar = progress(desc="evaluate", quiet=quiet)
    try:
        result = run_evaluate(pred, gt, pred_system=pred_system, gt_system=gt_system, output=output, keys=keys,
                              protocols=protos, align=align, by=by, yaw_bins=yaw_bins, report=report, plots=plots,
                              rejects=rejects, use_pred=pred_columns or use, use_gt=gt_columns or use,
                              radians=radians, overwrite=overwrite, batch_size=batch_size, progress=bar,
                              strict=strict, join_mode=join_mode, orthonormalize=orthonormalize, html=html,
                              worst=worst, images=images)
    except JoinUsageError as exc:
        raise click.UsageError(str(exc)) from None
    finally:
        bar.close()
    if not quiet:
        lines = format_table(result)
        to_err = report == "-"
        for line in lines:
            click.echo(line, err=to_err)
    outs = [str(p) for p in (report if report != "-" else None, output, rejects, plots, html) if p]
    if outs:
        echo_summary(["wrote " + ", ".join(outs)], quiet)


evaluate.help = evaluate.help.replace("{protocols}", _protocol_help())


def _v(x, w=8):
    return f"{x:{w}.3f}" if isinstance(x, (int, float)) and x is not None else f"{'-':>{w}}"


def format_table(result: dict) -> list:
    """The readable summary: counts, one line per metric, one line per protocol."""
    n = result["n"]
    lines = [f"pairs {n['pairs']} of {n['gt']} GT rows ({n['pred']} predictions): missing {n['missing']}, "
             f"invalid {n['invalid']}, unmatched predictions {n.get('unmatched_pred', 0)}; "
             f"systems pred {result['systems']['pred']}, gt {result['systems']['gt']}"]
    al = result.get("align", {})
    if al.get("method") == "mean":
        a = al["offset_angles"]
        lines.append(f"aligned: removed a constant offset of {al['offset_deg']:.3f} deg "
                     f"(pitch {a['pitch']:.3f}, yaw {a['yaw']:.3f}, roll {a['roll']:.3f} in {al['gt_system']}); "
                     f"geodesic mean before {al['before']['metrics']['geodesic']['mean'] or 0:.3f}")
    m = result["metrics"]
    g = m["geodesic"]
    lines.append(f"{'metric':<16}{'pitch':>8}{'yaw':>8}{'roll':>8}{'mean':>8}   detail")
    lines.append(f"{'geodesic':<16}{'':>24}{_v(g['mean'])}   median {_v(g['median'], 0)}, p90 {_v(g['p90'], 0)}, "
                 f"p95 {_v(g['p95'], 0)}, max {_v(g['max'], 0)}; within 5/10/15/30: "
                 + "/".join(f"{g[f'within_{t}']:.3f}" if g[f'within_{t}'] is not None else "-" for t in (5, 10, 15, 30)))
    mv = m["maev"]
    lines.append(f"{'maev':<16}{'':>24}{_v(mv['mean'])}   left {_v(mv['left'], 0)}, down {_v(mv['down'], 0)}, "
                 f"front {_v(mv['front'], 0)}")
    lines.append(f"{'frobenius':<16}{'':>24}{_v(m['frobenius']['mean'])}   ||I - P G^T||_F (unitless)")
    for k in ("mae_wrapped", "mae_best_of_two"):
        e = m[k]
        lines.append(f"{k:<16}{_v(e['pitch'])}{_v(e['yaw'])}{_v(e['roll'])}{_v(e['mean'])}")
    if result.get("protocols"):
        lines.append(f"{'protocol':<16}{'pitch':>8}{'yaw':>8}{'roll':>8}{'mean':>8}{'n':>9}{'dropped':>9}   extras")
        for name, p in result["protocols"].items():
            extras = []
            for k, v in p.items():
                if k in ("n", "dropped", "pitch", "yaw", "roll", "mean", "system", "source", "notes") or \
                        k.startswith("rotvec_"):
                    continue
                if isinstance(v, dict):
                    extras.append(f"{k} " + _v(v.get("mean"), 0).strip() + (f" (n {v['n']})" if "n" in v else ""))
                else:
                    extras.append(f"{k} {_v(v, 0).strip()}")
            lines.append(f"{name:<16}{_v(p['pitch'])}{_v(p['yaw'])}{_v(p['roll'])}{_v(p['mean'])}{p['n']:>9}"
                         f"{p['dropped']:>9}   " + ", ".join(extras))
        for note in result.get("notes", []):
            lines.append(f"note: {note}")
    if result.get("rejects"):
        lines.append("rejects: " + ", ".join(f"{k} {v}" for k, v in result["rejects"].items()))
    return lines
