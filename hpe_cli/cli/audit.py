"""``hpe audit``: per-row checks of a label table, a JSON report, plots and a flagged table."""
from __future__ import annotations

import click

from .table_options import column_options

from .options import SYSTEM, batch_option, echo_summary, output_option, overwrite_option, progress, verbosity_options

#: columns that identify a sample, used (when present) in the ``duplicates`` key
ID_COLUMNS = ("file", "image", "image_id", "id", "path", "person_id", "face_id", "frame", "camera",
              "bbox_x", "bbox_y", "bbox_w", "bbox_h")
_HASH_KEY = "hpe-audit-key-01"
_SEEDS = (0x9E3779B97F4A7C15, 0xD1B54A32D192ED03)


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("input", type=click.Path(exists=True))
@click.option("--system", "system", type=SYSTEM, default="300w_lp", show_default=True,
              help="Rotation system of the labels: a built-in name (see `hpe systems`) or a .toml file.")
@click.option("--json", "report", type=click.Path(dir_okay=False, allow_dash=True),
              help="Write the report (counts, settings, example rows) as JSON; '-' prints it.")
@click.option("--plots", type=click.Path(file_okay=False),
              help="Folder for yaw/pitch/roll histograms, a yaw-pitch coverage map (PNG) and index.html.")
@output_option(required=False, help="Write the table with one boolean column per check plus 'flagged' "
                                    "(.parquet or .csv).")
@click.option("--only-flagged", is_flag=True, help="With -o, write only the rows with at least one flag.")
@click.option("--gimbal-tol", type=click.FloatRange(0, 90), default=1.0, show_default=True,
              help="near_gimbal: the middle angle within this many degrees of its gimbal lock.")
@click.option("--radians", is_flag=True, help="INPUT angle columns are in radians.")
@click.option("--columns", "use", type=click.Choice(["auto", "angles", "matrix"]), default="auto",
              show_default=True, help="Audit pitch,yaw,roll or r00..r22 (auto: angles when present).")
@click.option("--key", "keys", multiple=True, metavar="COLUMN",
              help="Column identifying a sample for 'duplicates' (repeatable; default: any of file, image, "
                   "image_id, id, path, person_id, face_id, frame, camera, bbox_*).")
@click.option("--examples", type=click.IntRange(0), default=5, show_default=True,
              help="Example rows per check in the JSON report.")
@click.option("--strict", is_flag=True, help="Exit with status 1 when any row is flagged.")
@overwrite_option
@batch_option
@verbosity_options
@column_options
@click.pass_context
def audit(ctx, input, system, report, plots, output, only_flagged, gimbal_tol, radians, use, keys, examples,
          strict, overwrite, batch_size, verbose, quiet):
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

    The exit status is 0 whatever is found, unless --strict (1 if any row
    is flagged). Errors (unreadable input, missing columns) exit 1.

    \b
    Examples:
      hpe audit labels.parquet --system 300w_lp --json report.json
      hpe audit AFLW2000/ --json - --plots audit_plots/
      hpe audit preds.csv --system 6drepnet --columns matrix -o flagged.parquet --only-flagged
      hpe audit labels.csv --system whenet --gimbal-tol 2 --strict
    """
    bar = progress(desc="audit", quiet=quiet)
    try:
        result = run_audit(input, system, report=report, plots=plots, output=output, only_flagged=only_flagged,
                           near_tol_deg=gimbal_tol, radians=radians, use=use, keys=keys, n_examples=examples,
                           overwrite=overwrite, batch_size=batch_size, progress=bar)
    finally:
        bar.close()
    from ..rotation.audit import CHECKS

    flagged = result["details"]["flagged"]
    lines = [f"audit of {input}: {result['rows']} rows ({result['label_columns']}, system {system.name}), "
             f"{flagged} flagged",
             "  " + ", ".join(f"{c} {result[c]}" for c in CHECKS)]
    for c in CHECKS:
        if verbose and result["examples"].get(c):
            lines.append(f"  e.g. {c}: rows " + ", ".join(str(e["row"]) for e in result["examples"][c]))
    outs = [str(p) for p in (report if report != "-" else None, output, plots) if p]
    if outs:
        lines.append("  wrote " + ", ".join(outs))
    echo_summary(lines, quiet)
    if strict and flagged:
        ctx.exit(1)


def _fmix(x):
    """SplitMix64 finaliser: a bijective, well-mixing map of uint64 arrays (wraps on overflow)."""
    import numpy as np

    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _words(values):
    """float64 values as exact uint64 words: -0.0 -> 0.0 and every NaN -> one NaN, so equal values match."""
    import numpy as np

    v = np.asarray(values, dtype=np.float64)
    return np.ascontiguousarray(np.where(np.isnan(v), np.nan, v + 0.0)).view(np.uint64)


def _key_words(batch, name):
    import numpy as np
    import pandas as pd
    import pyarrow as pa
    import pyarrow.compute as pc

    col = batch.column(batch.schema.get_field_index(name))
    t = col.type
    if pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t):
        return _words(pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False))
    return pd.util.hash_array(np.asarray(col.to_numpy(zero_copy_only=False), dtype=object),
                              hash_key=_HASH_KEY, categorize=False)


def _key_hashes(batch, label_values, key_cols):
    """Two 64-bit hashes per row of (label values, key columns), made with different seeds.

    Label values enter as their exact bits; text columns as one 64-bit SipHash.
    """
    import numpy as np

    lv = label_values.reshape(len(label_values), -1)
    words = [_words(lv[:, i]) for i in range(lv.shape[1])] + [_key_words(batch, c) for c in key_cols]
    out = np.empty((len(lv), 2), dtype=np.uint64)
    for j, seed in enumerate(_SEEDS):
        h = np.full(len(lv), seed, dtype=np.uint64)
        for w in words:
            h = _fmix(h ^ w)
        out[:, j] = h
    return out


def _read_labels(batch, use, radians):
    """Label values of one batch: (n, 3) degrees or (n, 3, 3); NaN where unusable."""
    import numpy as np

    from ..io import ANGLE_COLS, MATRIX_COLS, numeric_column

    names = ANGLE_COLS if use == "angles" else MATRIX_COLS
    values = np.stack([numeric_column(batch, c)[0] for c in names], axis=-1)
    if use == "angles":
        return np.rad2deg(values) if radians else values
    return values.reshape(-1, 3, 3)


def run_audit(input_path, system, *, report=None, plots=None, output=None, only_flagged=False,
              near_tol_deg=1.0, radians=False, use="auto", keys=(), n_examples=5, overwrite=False,
              batch_size=262_144, progress=None) -> dict:
    """Audit ``input_path`` and write the requested outputs; return the report dict."""
    import numpy as np

    from ..errors import HpeError
    from ..io import ANGLE_COLS, MATRIX_COLS, check_output, label_mode, open_table, write_json
    from ..io.plots import AngleHistograms, plot_files, write_plots
    from ..rotation.audit import CHECKS, audit_angles, audit_matrices, duplicate_first

    for p in (report if report != "-" else None, output):
        if p:
            check_output(p, overwrite)
    if output:
        from ..io import table_format

        table_format(output)
    if plots:
        from pathlib import Path

        if Path(plots).exists():
            for p in plot_files(plots).values():
                check_output(p, overwrite)

    src = open_table(input_path, batch_size)
    columns = src.columns
    mode = label_mode(columns, src.path) if use == "auto" else use
    need = ANGLE_COLS if mode == "angles" else MATRIX_COLS
    missing = [c for c in need if c not in columns]
    if missing:
        raise HpeError(f"{src.path}: missing column(s) {', '.join(missing)} for --columns {mode}")
    if keys:
        bad = [k for k in keys if k not in columns]
        if bad:
            raise HpeError(f"{src.path}: --key column(s) {', '.join(bad)} not in the table; "
                           f"expected some of: {', '.join(columns[:20])}")
        key_cols = list(dict.fromkeys(keys))
    else:
        key_cols = [c for c in ID_COLUMNS if c in columns]
    id_cols = [c for c in ("file", "image", "image_id", "id", "path") if c in columns][:1]
    if progress is not None and src.num_rows:
        progress.total = src.num_rows

    flags, hashes = [], []
    hist = AngleHistograms() if plots else None
    examples = {c: [] for c in CHECKS}
    rows = 0
    for batch in src.batches():
        values = _read_labels(batch, mode, radians)
        res = audit_angles(values, system, near_tol_deg) if mode == "angles" \
            else audit_matrices(values, system, near_tol_deg)
        flags.append(np.stack([res[c] for c in CHECKS[:-1]], axis=1))
        hashes.append(_key_hashes(batch, values, key_cols))
        if hist is not None:
            hist.add(values if mode == "angles" else res["primary"])
        for c in CHECKS[:-1]:
            want = n_examples - len(examples[c])
            if want > 0:
                for i in np.flatnonzero(res[c])[:want]:
                    examples[c].append(_example(batch, int(i), rows, id_cols, values, mode))
        rows += batch.num_rows
        if progress is not None:
            progress.update(batch.num_rows)

    flag_arr = np.concatenate(flags) if flags else np.zeros((0, len(CHECKS) - 1), dtype=bool)
    first = duplicate_first(np.concatenate(hashes)) if hashes else np.zeros(0, dtype=np.int64)
    dup = first != np.arange(rows)
    flag_arr = np.concatenate([flag_arr, dup[:, None]], axis=1)
    examples["duplicates"] = [{"row": int(i), "same_as": int(first[i])} for i in np.flatnonzero(dup)[:n_examples]]
    counts = {c: int(flag_arr[:, n].sum()) for n, c in enumerate(CHECKS)}
    any_flag = flag_arr.any(axis=1)

    result = {"rows": rows, **counts,
              "system": system.name, "input": str(src.path), "label_columns": mode,
              "units": "radians" if (radians and mode == "angles") else ("degrees" if mode == "angles" else None),
              "settings": {"near_gimbal_deg": near_tol_deg, "gimbal_lock_tol": system.gimbal_tol,
                           "lock_distance": "|cos| (or |sin| for proper Euler) of the middle angle",
                           "duplicate_key": (list(need) + key_cols)},
              "details": {"flagged": int(any_flag.sum()),
                          "near_gimbal_not_locked": int((flag_arr[:, 1] & ~flag_arr[:, 0]).sum())},
              "examples": examples}

    if output:
        _write_flagged(input_path, output, flag_arr, any_flag, only_flagged, overwrite, batch_size, system)
    if plots:
        write_plots(hist, plots, system, {"input": str(src.path), "system": system.name, "rows": rows,
                                          **counts, "flagged": result["details"]["flagged"]},
                    title=f"hpe audit: {src.path.name}", overwrite=overwrite)
    if report == "-":
        import json

        click.echo(json.dumps(result, indent=2))
    elif report:
        write_json(result, report, overwrite=overwrite)
    return result


def _example(batch, i, offset, id_cols, values, mode) -> dict:
    import numpy as np

    ex = {"row": offset + i}
    for c in id_cols:
        ex[c] = batch.column(c)[i].as_py()
    v = values[i]
    if mode == "angles":
        ex.update({k: (float(x) if np.isfinite(x) else str(x)) for k, x in zip(("pitch", "yaw", "roll"), v)})
    else:
        ex["matrix"] = [[(float(x) if np.isfinite(x) else str(x)) for x in r] for r in v]
    return ex


def _write_flagged(input_path, output, flag_arr, any_flag, only_flagged, overwrite, batch_size, system):
    """Second pass over the input: every column, then one boolean column per check and 'flagged'."""
    import pyarrow as pa

    from ..io import TableWriter, open_table, system_metadata
    from ..rotation.audit import CHECKS

    names = list(CHECKS) + ["flagged"]
    src = open_table(input_path, batch_size)
    keep = [c for c in src.columns if c not in names]
    meta = {**system_metadata(system), "hpe:audit_of": str(src.path)}
    offset = 0
    with TableWriter(output, overwrite, meta) as w:
        for batch in src.batches():
            n = batch.num_rows
            f = flag_arr[offset:offset + n]
            arrays = list(batch.select(keep).columns) + [pa.array(f[:, k]) for k in range(len(CHECKS))] \
                + [pa.array(any_flag[offset:offset + n])]
            out = pa.RecordBatch.from_arrays(arrays, names=keep + names)
            if only_flagged:
                out = out.filter(pa.array(any_flag[offset:offset + n]))
            if out.num_rows or w.rows == 0:
                w.write(out)
            offset += n
        if offset == 0:
            empty = pa.schema([src.schema.field(c) for c in keep] + [pa.field(c, pa.bool_()) for c in names])
            w.write(empty.empty_table())
