"""``hpe audit``: per-row checks of a label table, a JSON report, plots and a flagged table."""

from __future__ import annotations

import click

from .choices import RegistryChoice
from .options import (
    batch_option,
    columns_option,
    echo_summary,
    file_system_option,
    fmt_small,
    images_option,
    output_option,
    overwrite_option,
    progress,
    radians_option,
    rejects_option,
    threads_option,
    verbosity_options,
)
from .table_options import column_options


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@file_system_option()
@click.option(
    "--json",
    "report",
    type=click.Path(dir_okay=False, allow_dash=True),
    help="Write the report (counts, settings, example rows) as JSON; '-' prints it.",
)
@click.option(
    "--plots",
    type=click.Path(file_okay=False),
    help="Folder for yaw/pitch/roll histograms, a yaw-pitch coverage map (PNG) and index.html.",
)
@images_option(
    "With --plots: folder of the images, to draw the first flagged rows of each check on the page "
    "(default: INPUT's folder; a .mat folder holds its images)."
)
@output_option(
    required=False, help="Write the table with one boolean column per check plus 'flagged' (.parquet or .csv)."
)
@click.option("--only-flagged", is_flag=True, help="With -o, write only the rows with at least one flag.")
@click.option(
    "--gimbal-tol",
    type=click.FloatRange(0, 90),
    default=1.0,
    show_default=True,
    help="near_gimbal: the middle angle within this many degrees of its gimbal lock.",
)
@radians_option()
@columns_option("Audit pitch,yaw,roll or r00..r22 (auto: angles when present).")
@click.option(
    "--key",
    "keys",
    multiple=True,
    metavar="COLUMN",
    help="Column identifying a sample for 'duplicates' (repeatable; default: any of file, image, "
    "image_id, id, path, person_id, face_id, frame, camera, bbox_*).",
)
@click.option(
    "--examples",
    type=click.IntRange(0),
    default=5,
    show_default=True,
    help="Example rows per check in the JSON report.",
)
@click.option(
    "--strict",
    is_flag=True,
    help="Exit with status 1 when any row is flagged; with --rejects, a "
    "rejected row is an error and nothing is written.",
)
@rejects_option
@click.option(
    "--decoder",
    type=RegistryChoice("hpe_cli.rotation.decoders:DECODERS"),
    default=None,
    help="Also report how far this published decoder's printed angles are from each rotation "
    "(max/mean geodesic and per-angle, JSON key 'decoder').",
)
@click.option(
    "--consistency",
    is_flag=True,
    help="Also check each label against independent evidence: its 2-D landmarks, the other views of the "
    "head (calibrated cameras) and its neighbours in time; score and rank the rows (JSON key "
    "'consistency', columns in -o, worst rows on the --plots page). See docs/commands/audit.md.",
)
@click.option(
    "--calibration",
    type=click.Path(exists=True, dir_okay=False),
    help="With --consistency: Panoptic calibration JSON for the views check [default: the one "
    "`hpe relabel-panoptic` recorded in INPUT's metadata].",
)
@click.option(
    "--suspects",
    type=click.Path(dir_okay=False),
    help="With --consistency: write the suspect rows' key columns with 'score' and 'reason' "
    "(.csv or .parquet), for `hpe export/convert --exclude`.",
)
@click.option(
    "--max-jump",
    type=click.FloatRange(0, min_open=True),
    default=5.0,
    show_default=True,
    help="With --consistency: a label that leaves the interpolation of its neighbouring frames by more than "
    "this many degrees per frame is a jump.",
)
@click.option(
    "--suspect-score",
    type=click.FloatRange(0, min_open=True),
    default=3.0,
    show_default=True,
    help="With --consistency: rows scoring above this are suspects (1 = the disagreement expected for the row).",
)
@overwrite_option
@batch_option
@threads_option
@verbosity_options
@column_options
@click.pass_context
def audit(
    ctx,
    input,
    system,
    report,
    plots,
    images,
    output,
    only_flagged,
    gimbal_tol,
    radians,
    use,
    keys,
    examples,
    strict,
    rejects,
    decoder,
    consistency,
    calibration,
    suspects,
    max_jump,
    suspect_score,
    overwrite,
    batch_size,
    threads,
    verbose,
    quiet,
):
    """Check every row of a label table and count what looks wrong.

    INPUT is a .parquet or .csv table with angle columns pitch,yaw,roll
    (degrees, or --radians) or matrix columns r00..r22 (row-major, the
    system's stored matrix), or a folder of 300W-LP/AFLW2000 .mat files.

    \b
    Checks (JSON report keys; -o column names):
      rows           rows read
      gimbal_lock    numerically locked: the system's lock distance (|cos|
                     of the middle angle) below its gimbal_tol (1e-4)
      near_gimbal    middle angle within --gimbal-tol degrees of the lock,
                     where pitch and roll cannot be split reliably;
                     includes the gimbal_lock rows
      non_canonical  angles that are a valid rotation but not the system's
                     primary solution (yaw 120 in 300w_lp); never set for
                     locked rows or matrix input
      out_of_range   an angle outside (-180, 180] or the system's declared
                     range (matrix input: its primary angles)
      non_finite     a missing, non-numeric, NaN or infinite label value
      not_rotation   matrix input whose finite entries are not a rotation
      duplicates     same label values and id columns (see --key) as an
                     earlier row; the first occurrence is not counted

    \b
    With --consistency (columns of -o; a row no check applies to is "not
    checked", never consistent):
      landmark_angle     degrees between the label and the rotation fitted
                         to the row's 2-D landmarks (lm*_x/y, 21/68/70
                         points, or a .mat folder's pt2d)
      landmark_residual  that fit's RMS error per inter-ocular distance
      view_angle         degrees to the consensus of the other cameras'
                         labels of the head at that frame (calibration)
      jump_rate          degrees per frame away from the neighbours' path
      consistency_score  largest of the checks over what is expected
      suspect            score above --suspect-score
      consistency_note   why suspect, or why not checked

    The exit status is 0 whatever is found, unless --strict (1 if any row
    is flagged). Errors (unreadable input, missing columns) exit 1; rows
    the reader cannot parse go to --rejects FILE when given (the rest is
    audited), else the first one is the error.

    \b
    Examples:
      hpe audit labels.parquet --system 300w_lp --json report.json
      hpe audit AFLW2000/ --json - --plots audit_plots/
      hpe audit labels.parquet --plots audit_plots/ --images frames/
      hpe audit preds.csv --system 6drepnet --columns matrix -o flagged.parquet --only-flagged
      hpe audit labels.csv --system whenet --gimbal-tol 2 --strict
      hpe audit AFLW2000/ --decoder synergynet --json -
      hpe audit img2pose_preds.csv --system img2pose --json report.json
      hpe audit messy.csv --rejects unreadable.csv --json report.json
      hpe audit AFLW2000/ --consistency --json - --suspects suspects.csv
      hpe audit panoptic_labels.parquet --consistency -o scored.parquet --plots audit/
    """
    from ..pipelines.audit import AuditOptions, run_audit

    if not consistency and (calibration or suspects):
        raise click.UsageError("--calibration and --suspects need --consistency")
    settings = None
    if consistency:
        from ..pipelines.audit import ConsistencySettings

        settings = ConsistencySettings(calibration=calibration, max_jump_deg=max_jump, suspect_score=suspect_score)
    options = AuditOptions(
        report=report,
        plots=plots,
        output=output,
        only_flagged=only_flagged,
        near_tol_deg=gimbal_tol,
        radians=radians,
        use=use,
        keys=keys,
        n_examples=examples,
        overwrite=overwrite,
        batch_size=batch_size,
        decoder=decoder,
        threads=threads,
        images=images,
        rejects=rejects,
        strict=strict,
        consistency=settings,
        suspects=suspects,
    )
    bar = progress(desc="audit", quiet=quiet)
    try:
        result = run_audit(input, system, options, progress=bar, echo=click.echo)
    finally:
        bar.close()
    from ..rotation.audit import CHECKS

    flagged = result["details"]["flagged"]
    lines = [
        f"audit of {input}: {result['rows']} rows ({result['label_columns']}, system {result['system']} "
        f"from {result['system_origin']}), "
        f"{flagged} flagged",
        "  " + ", ".join(f"{c} {result[c]}" for c in CHECKS),
    ]
    for c in CHECKS:
        if verbose and result["examples"].get(c):
            lines.append(f"  e.g. {c}: rows " + ", ".join(str(e["row"]) for e in result["examples"][c]))
    if "decoder" in result:
        d = result["decoder"]
        lines.append(
            f"  decoder {d['decoder']} vs {d['reference_system']}: geodesic max {fmt_small(d['geodesic_deg']['max'])} "
            f"mean {fmt_small(d['geodesic_deg']['mean'])} deg; |d_yaw| max {fmt_small(d['d_yaw']['max'])}, |d_pitch| "
            f"max {fmt_small(d['d_pitch']['max'])}, |d_roll| max {fmt_small(d['d_roll']['max'])} deg; "
            f"{d['rows_off_by_more_than_0.01deg']} rows off by > 0.01 deg; {d['not_decoded']} not decoded"
        )
    if "consistency" in result:
        c = result["consistency"]
        lines.append(
            f"  consistency: {c['checked']} checked, {c['not_checked']} not checked, {c['suspects']} suspects"
            + (
                f"; cameras with an offset: {', '.join(c['views']['cameras_with_offset'])}"
                if c["views"].get("cameras_with_offset")
                else ""
            )
        )
    if result["rejected"]:
        lines.append(f"  {result['rejected']} unreadable row(s) not audited -> {rejects}")
    outs = [str(p) for p in (report if report != "-" else None, output, plots, suspects) if p]
    if outs:
        lines.append("  wrote " + ", ".join(outs))
    if strict and flagged:  # one line naming what was found (the outputs are not written: the run failed)
        from ..errors import HpeError

        found = ", ".join(f"{c} {result[c]}" for c in CHECKS if result[c])
        raise HpeError(f"{input}: {flagged} of {result['rows']} rows flagged ({found}); --strict: nothing written")
    echo_summary(lines, quiet)
