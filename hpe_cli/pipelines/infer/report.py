"""``hpe infer``'s answer: the summary lines of a report, the JSON report and the system TOML written."""

from __future__ import annotations

from ...errors import HpeError
from ...io import AtomicFile, write_json
from ...io.transaction import current
from ...rotation import infer as inf


def _small(x, spec: str = ".2g") -> str:
    """``x`` to 2 digits, or ``< 1e-12`` at rounding level (its digits differ between CPUs; as
    :func:`hpe_cli.cli.options.fmt_small`)."""
    return "< 1e-12" if 0 <= float(x) < 1e-12 else format(float(x), spec)


def report_lines(rep: dict) -> list:
    """The human-readable summary of an infer report (:func:`hpe_cli.rotation.infer.report_json`), as lines."""
    lines = []
    echo = lines.append
    if rep["mode"] == "landmarks":
        m = rep["matched"]
        echo(
            f"best: {rep['best']} ({rep['fit']}; RMS residual {rep['rms_residual_deg']:.2f} deg, median "
            f"{rep['median_residual_deg']:.2f} deg over {rep['samples']} faces; next candidate "
            f"{rep['separation']:.1f}x worse)"
        )
        echo(f"  {m['formula']}")
        echo("  built-in readings of the labels (RMS / max residual, deg):")
        for h in rep["hypotheses"]:
            echo(f"    {h['rms_residual_deg']:7.2f} {h['max_residual_deg']:7.2f}  {', '.join(h['readings'])}")
        if rep.get("warning"):
            echo(f"  warning: {rep['warning']}")
        worst = sorted(rep["per_face"], key=lambda f: -f["residual_deg"])[:3]
        echo("  largest per-face residuals: " + ", ".join(f"{f['id']} {f['residual_deg']:.2f} deg" for f in worst))
        return lines
    if rep["fit"] == "exact":
        m = rep["matched"]
        echo(
            f"best: {rep['best']} (exact; max Frobenius error {_small(rep['max_error'])} over {rep['samples']} samples)"
        )
        echo(f"  {m['formula']}")
        echo(f"  {m['turns']}")
        if m["transpose_of"]:
            echo(f"  (the transpose of the matrix of {', '.join(m['transpose_of'])})")
        if rep.get("also_matches"):
            echo(
                f"  also reproduced by built-in: {', '.join(rep['also_matches']['names'])} "
                "(same matrix from the same angles)"
            )
        if rep.get("selection"):
            echo(f"  solution kept by the decoder: {rep['selection']['rule']}")
        if rep.get("near_lock"):
            echo(
                f"  {rep['near_lock']['count']} samples near gimbal lock handled differently "
                f"(max error {_small(rep['near_lock']['max_error'])})"
            )
        if rep.get("ambiguous"):
            echo(f"  warning: {rep['ambiguous']}")
    else:
        m = rep["best_partial"]
        names = f" ({', '.join(m['builtins'])})" if m["builtins"] else ""
        echo(
            f"no exact fit. best partial fit: {m['formula']}{names}: {m['explained']} of {rep['samples']} "
            f"samples explained, median error {_small(m['median_error'], '.3g')}"
        )
        if "breaks" in m:
            echo(f"  {m['breaks']['summary']}")
    for e in rep.get("runners_up", [])[:3]:
        echo(f"  runner-up: {e['formula']}  max error {_small(e['max_error'], '.3g')}")
    return lines


def finish(rep: dict, what: str, *, json_path=None, output=None, overwrite=False, echo=None) -> tuple:
    """Write the JSON report, show its summary (``echo`` per line) and, for a fit, write the system TOML.

    Returns ``(report, written)``: the JSON report and the ``wrote ...`` line (None without ``output``).

    Raises
    ------
    HpeError
        Nothing fits (the JSON report is still kept: it explains why; nothing is
        written to ``output``).
    """
    # lazy: the spawned child of --callable/--decoder loads this package, and needs no I/O layer

    report = inf.report_json(rep)
    if json_path is not None:
        write_json(report, json_path, overwrite)
    if echo is not None:
        for line in report_lines(report):
            echo(line)
    if rep["fit"] not in ("exact", "clear"):
        txn = current()
        if txn is not None:  # the report explains the failure: keep it (nothing is written with -o)
            txn.commit()
        tail = "; nothing written to " + output if output else ""
        if rep["mode"] == "landmarks":
            raise HpeError(
                f"{what}: no system explains the landmarks clearly ({rep['fit']}: best {rep['best']}, "
                f"RMS residual {rep['rms_residual_deg']:.2f} deg){tail}"
            )
        raise HpeError(
            f"{what}: no rotation system reproduces it exactly (best partial fit "
            f"{rep['best_partial']['formula']}, max error {_small(rep['max_error'], '.3g')}){tail}"
        )
    written = None
    if output is not None:
        with AtomicFile(output, overwrite) as tmp:
            tmp.write_text(rep["_system_toml"], encoding="utf-8")
        written = f"wrote {output} (system {rep['_system_name']})"
    return report, written
