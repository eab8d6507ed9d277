"""``hpe evaluate``: score head-pose predictions against ground truth, every published protocol by name."""
from __future__ import annotations

import click

from .table_options import column_options

from .options import SYSTEM, batch_option, echo_summary, output_option, overwrite_option, progress, \
    rejects_options, verbosity_options

_PROTOCOL_NAMES = ("hopenet", "fsanet", "6drepnet", "6drepnet360", "directmhp", "whenet", "opal23",
                   "headposeplus", "img2pose", "dad3dheads")


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
@click.option("--pred-system", type=SYSTEM, default=None,
              help="Rotation system of PRED (name or .toml) [default: the file's own; required for files that "
                   "name none].")
@click.option("--gt-system", type=SYSTEM, default=None,
              help="Rotation system of GT (name or .toml) [default: the file's own; required for files that "
                   "name none].")
@click.option("--key", "keys", multiple=True, callback=_split_keys, metavar="COL[,COL...]",
              help="Join columns (default: 'image' if both tables have it, else 'file', else row order).")
@click.option("--protocol", "protocols", multiple=True, type=click.Choice(_PROTOCOL_NAMES + ("all",)),
              help="Published protocol to reproduce (repeatable; default: all).")
@click.option("--align", type=click.Choice(["none", "mean"]), default="none", show_default=True,
              help="mean: remove the constant rotation offset between GT and predictions first.")
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
def evaluate(pred, gt, output, pred_system, gt_system, keys, protocols, align, by, yaw_bins, report, plots, rejects,
             use, pred_columns, gt_columns, radians, overwrite, batch_size, verbose, quiet, strict):
    """Score predictions PRED against ground truth GT, each in its own system.

    PRED and GT are any tables hpe reads (.parquet, .csv, a folder of .mat
    files, BIWI files), holding angles (pitch,yaw,roll) or matrices (r00..r22).
    Every rotation is brought to one frame through its matrix, so the two
    sides may use different conventions. Rows are joined on --key; a GT row
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

    \b
    Protocols (--protocol; each reproduces the published code named):
      hopenet       300w_lp, |d|, no wrap, no filter       deep-head-pose code/test_hopenet.py
      fsanet        300w_lp, |d|, GT |angles| <= 99         FSA-Net training_and_testing/FSANET_test.py
      6drepnet      6drepnet, min(|d|,|d+-360|,|d+-180|),   6DRepNet sixdrepnet/test.py
                    GT |angles| <= 99 (the +-180 terms hide flipped answers)
      6drepnet360   6drepnet, the same five-term min, no    6DRepNet360 sixdrepnet360/test.py
                    filter; vmae (column angles)
      directmhp     whenet, |d| with only yaw wrapped;      DirectMHP utils/mae.py
                    front |GT yaw| <= 90, back > 90
      whenet        whenet, every angle wrapped; narrow     WHENet paper (no script published)
                    |GT yaw| <= 90
      opal23        GT system, better of two solutions,     opal23_headpose test/evaluator.py
                    wrapped; geodesic
      headposeplus  |d| in pyr (biwi) and ypr (300w_lp)     headposeplus hpp/calc_error.py
      img2pose      |d| of rotation-vector components       img2pose evaluation/jupyter_notebooks/
                    (opencv frame), GT |angles| <= 99         aflw_2000_3d_evaluation.ipynb
      dad3dheads    mean ||I - P G^T||_F                    DAD-3DHeads dad_3dheads_benchmark/benchmark.py
    Plain |d| protocols compare Euler branches: a correct rotation stated
    with the other solution scores a large error. The report says so.

    \b
    Examples:
      hpe evaluate preds.csv AFLW2000/ --pred-system 6drepnet --gt-system 300w_lp
      hpe evaluate preds.parquet gt.parquet --pred-system whenet --gt-system whenet \\
          --protocol directmhp --protocol whenet -o errors.parquet --json report.json
      hpe evaluate preds.csv gt.csv --pred-system opencv --gt-system biwi --key image,person_id \\
          --align mean --by sequence --yaw-bins 15 --plots eval_plots/ --rejects rejects.csv
      hpe evaluate preds.csv gt.csv --pred-system 6drepnet --gt-system 300w_lp --columns matrix --json -
    """
    from ..pipelines.evaluate import run_evaluate

    protos = None if (not protocols or "all" in protocols) else list(protocols)
    bar = progress(desc="evaluate", quiet=quiet)
    try:
        result = run_evaluate(pred, gt, pred_system=pred_system, gt_system=gt_system, output=output, keys=keys,
                              protocols=protos, align=align, by=by, yaw_bins=yaw_bins, report=report, plots=plots,
                              rejects=rejects, use_pred=pred_columns or use, use_gt=gt_columns or use,
                              radians=radians, overwrite=overwrite, batch_size=batch_size, progress=bar,
                              strict=strict)
    finally:
        bar.close()
    if not quiet:
        lines = format_table(result)
        to_err = report == "-"
        for line in lines:
            click.echo(line, err=to_err)
    outs = [str(p) for p in (report if report != "-" else None, output, rejects, plots) if p]
    if outs:
        echo_summary(["wrote " + ", ".join(outs)], quiet)


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
