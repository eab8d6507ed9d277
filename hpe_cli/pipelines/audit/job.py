"""``hpe audit`` as a streaming job: per-row checks, duplicates, report, plots and a flagged table.

Memory is flat in the number of rows apart from one 64-bit hash per row
(duplicates): the checks are counted batch by batch, the label columns are
checked as columns (no ``(N, 3, 3)`` stacks), and the optional ``-o`` table is
written in a second pass that recomputes each batch's flags.

Row numbers in the report are 1-based file lines (header = line 1; for
Parquet, the line the row would have in a CSV with a header).
"""

from __future__ import annotations

import numpy as np

from ...errors import HpeError
from ..inorder import in_order

#: columns that identify a sample, used (when present) in the ``duplicates`` key
ID_COLUMNS = (
    "file",
    "image",
    "image_id",
    "id",
    "path",
    "person_id",
    "face_id",
    "frame",
    "camera",
    "bbox_x",
    "bbox_y",
    "bbox_w",
    "bbox_h",
)
_SEED = 0x9E3779B97F4A7C15
_STR_MULT = np.uint64(0x100000001B3)  # FNV-style odd multiplier for the polynomial string hash
_NULL_WORD = np.uint64(0x6A09E667F3BCC909)


# ------------------------------------------------------------------------------------------------- hashing
def _fmix(x):
    """SplitMix64 finaliser: a bijective, well-mixing map of uint64 arrays (wraps on overflow)."""
    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _words(values):
    """float64 values as exact uint64 words: -0.0 -> 0.0 and every NaN -> one NaN, so equal values match."""
    v = np.asarray(values, dtype=np.float64)
    return np.ascontiguousarray(np.where(np.isnan(v), np.nan, v + 0.0)).view(np.uint64)


_POW = None


def _powers(n):
    """``_STR_MULT ** k mod 2**64`` for k < n (cached, grown on demand)."""
    global _POW
    if _POW is None or len(_POW) < n:
        m = max(n, 256, 2 * (0 if _POW is None else len(_POW)))
        p = np.full(m, _STR_MULT, dtype=np.uint64)
        p[0] = 1
        with np.errstate(over="ignore"):
            _POW = np.cumprod(p, dtype=np.uint64)
    return _POW


def string_hashes(col) -> np.ndarray:
    """One 64-bit hash per value of an Arrow string/binary array, from its buffers (no Python strings).

    A polynomial hash of the bytes modulo 2**64 mixed with the length, then
    SplitMix64; nulls get a fixed word. Processed in slices of about 4 MB of
    text so temporaries stay small.
    """
    import pyarrow as pa

    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_string(col.type) or pa.types.is_binary(col.type):
        off_type = np.int32
    else:
        col = col.cast(pa.large_string()) if not pa.types.is_large_binary(col.type) else col
        off_type = np.int64
    n = len(col)
    out = np.empty(n, dtype=np.uint64)
    if n == 0:
        return out
    bufs = col.buffers()
    offsets = np.frombuffer(bufs[1], dtype=off_type, count=n + 1, offset=col.offset * np.dtype(off_type).itemsize)
    data = np.frombuffer(bufs[2], dtype=np.uint8) if bufs[2] is not None else np.zeros(0, dtype=np.uint8)
    lengths = np.diff(offsets).astype(np.int64)
    step = max(1, int((4 << 20) / max(1.0, float(lengths.mean()))))
    with np.errstate(over="ignore"):
        for lo in range(0, n, step):
            hi = min(n, lo + step)
            s0, s1 = int(offsets[lo]), int(offsets[hi])
            ln = lengths[lo:hi]
            h = _fmix(ln.astype(np.uint64) ^ np.uint64(_SEED))
            if s1 > s0:
                b = data[s0:s1].astype(np.uint64) + np.uint64(1)
                rel = np.repeat(offsets[lo:hi].astype(np.int64) - s0, ln)
                pos = np.arange(s1 - s0, dtype=np.int64) - rel
                b *= _powers(int(ln.max()))[pos]
                starts = offsets[lo:hi].astype(np.int64) - s0
                nz = ln > 0
                sums = np.zeros(hi - lo, dtype=np.uint64)
                sums[nz] = np.add.reduceat(b, starts[nz])
                h = _fmix(h ^ sums)
            out[lo:hi] = h
    if col.null_count:
        out[np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)] = _NULL_WORD
    return out


def _key_words(batch, name):
    import pyarrow as pa
    import pyarrow.compute as pc

    col = batch.column(batch.schema.get_field_index(name))
    t = col.type
    if pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t):
        return _words(pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False))
    if not (
        pa.types.is_string(t) or pa.types.is_large_string(t) or pa.types.is_binary(t) or pa.types.is_large_binary(t)
    ):
        col = pc.cast(col, pa.string())
    return string_hashes(col)


def key_hashes(label_cols, batch, key_cols) -> np.ndarray:
    """One 64-bit hash per row of (label values, key columns): equal rows get equal hashes.

    Label values enter as their exact bits (-0.0 = 0.0, all NaNs equal); text
    columns as a 64-bit hash of their bytes.
    """
    n = len(label_cols[0])
    h = np.full(n, _SEED, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for w in [_words(c) for c in label_cols] + [_key_words(batch, c) for c in key_cols]:
            h = _fmix(h ^ w)
    return h


# ------------------------------------------------------------------------------------------------- labels
def _label_cols(batch, mode, radians):
    """Label columns of one batch as float64 arrays; NaN where missing or non-numeric."""
    from ...io import ANGLE_COLS, MATRIX_COLS
    from ...io.labels import _numeric

    names = ANGLE_COLS if mode == "angles" else MATRIX_COLS
    cols = []
    for c in names:
        v, _, _ = _numeric(batch, c)  # NaN where missing or non-numeric, inf kept
        cols.append(np.rad2deg(v) if (radians and mode == "angles") else v)
    if mode == "angles":
        from ...io.units_watch import observe_degrees, observe_radians  # warn at the end if the unit looks wrong

        if radians:
            observe_radians([np.deg2rad(c) for c in cols])
        else:
            observe_degrees(cols)
    return cols


def _checks(cols, mode, system, near_tol_deg):
    from ...rotation.audit import audit_columns

    return audit_columns(cols, system, mode, near_tol_deg, lock_distance=False)


def _example(batch, i, line, id_cols, cols, mode) -> dict:
    ex = {"row": int(line)}
    for c in id_cols:
        ex[c] = batch.column(c)[i].as_py()
    v = [float(c[i]) for c in cols]
    f = [(x if np.isfinite(x) else str(x)) for x in v]
    if mode == "angles":
        ex.update(dict(zip(("pitch", "yaw", "roll"), f)))
    else:
        ex["matrix"] = [f[0:3], f[3:6], f[6:9]]
    return ex


# ------------------------------------------------------------------------------------------------- duplicates
class _Duplicates:
    """Duplicates from one 64-bit hash per row (8 bytes a row; the only per-row state of an audit)."""

    def __init__(self):
        self.parts = []
        self.batch_sizes = []
        self.lines = []  # (row index, line) where the line numbering jumps (CSV rejects, blank lines)
        self.n = 0
        self._prev_line = None

    def add(self, h, lines):
        self.parts.append(h)
        self.batch_sizes.append(len(h))
        if len(lines):
            jumps = np.flatnonzero(np.diff(lines) != 1) + 1
            if self._prev_line is None or lines[0] != self._prev_line + 1:
                self.lines.append((self.n, int(lines[0])))
            for j in jumps:
                self.lines.append((self.n + int(j), int(lines[j])))
            self._prev_line = int(lines[-1])
        self.n += len(h)

    def finish(self):
        """Compute the duplicate rows; returns their count."""
        H = np.concatenate(self.parts) if self.parts else np.zeros(0, dtype=np.uint64)
        self.parts = []
        self.H = H
        self.dup_idx = np.zeros(0, dtype=np.int64)
        self.first_idx = np.zeros(0, dtype=np.int64)
        if len(H) < 2:
            return 0
        S = np.sort(H)
        same = S[1:] == S[:-1]
        if not same.any():
            return 0
        dupvals = np.unique(S[1:][same])
        del S, same
        idx = []
        for lo in range(0, len(H), 1 << 20):
            chunk = H[lo : lo + (1 << 20)]
            pos = np.minimum(np.searchsorted(dupvals, chunk), len(dupvals) - 1)
            idx.append(np.flatnonzero(dupvals[pos] == chunk) + lo)
        idx = np.concatenate(idx)
        vals = H[idx]
        uniq, first = np.unique(vals, return_index=True)
        first_of = idx[first[np.searchsorted(uniq, vals)]]
        is_dup = first_of != idx
        self.dup_idx = idx[is_dup]
        self.first_idx = first_of[is_dup]
        return int(is_dup.sum())

    def line_of(self, i):
        i = np.asarray(i, dtype=np.int64)
        if not self.lines:
            return i + 2
        starts = np.array([s for s, _ in self.lines], dtype=np.int64)
        first = np.array([ln for _, ln in self.lines], dtype=np.int64)
        k = np.searchsorted(starts, i, side="right") - 1
        return first[k] + (i - starts[k])

    def mask(self, lo, hi):
        a, b = np.searchsorted(self.dup_idx, [lo, hi])
        m = np.zeros(hi - lo, dtype=bool)
        m[self.dup_idx[a:b] - lo] = True
        return m


# ------------------------------------------------------------------------------------------------- job
def _source(input_path, batch_size):
    from ...io import open_table

    return open_table(input_path, batch_size, with_lines=True)


def _batches(src, mode, path, rejects=None):
    """``(batch, lines, label cols)``; a row the reader sets aside fails the audit, naming its line.

    A non-numeric label value is not such a row: it is read as NaN and
    counted as ``non_finite``, like today. With a rejects file (``rejects``
    with a path), the rows the reader sets aside go there instead.
    """
    from ...io import ANGLE_COLS, MATRIX_COLS
    from ...io.readers import LINE_COL

    label = {f"non-numeric value in {c}" for c in (ANGLE_COLS if mode == "angles" else MATRIX_COLS)}
    rejects_file = rejects
    for batch, rejects in src.batches_with_rejects():
        unread = [r for r in rejects if r.reason in label]
        other = [r for r in rejects if r.reason not in label]
        if other and rejects_file is not None and rejects_file.path is not None:
            rejects_file.add_unreadable(other)
            rejects = unread
        if len(unread) < len(rejects):
            r = next(r for r in rejects if r.reason not in label)
            raise HpeError(
                f"{src.where(r.line)}: {r.reason} ({len(rejects) - len(unread)} unreadable rows in "
                "this block; use --rejects FILE to set them aside and audit the rest)"
            )
        lines = batch.column(LINE_COL).to_numpy()
        yield batch.drop_columns([LINE_COL]), lines, unread


def run_audit(
    input_path,
    system,
    *,
    report=None,
    plots=None,
    output=None,
    only_flagged=False,
    near_tol_deg=1.0,
    radians=False,
    use="auto",
    keys=(),
    n_examples=5,
    overwrite=False,
    batch_size=65_536,
    progress=None,
    echo=None,
    decoder=None,
    workers=None,
    images=None,
    rejects_path=None,
    strict_rejects=False,
    consistency=None,
    suspects=None,
) -> dict:
    """Audit ``input_path`` and write the requested outputs; return the report dict.

    Batches are checked and hashed on ``workers`` threads (default: one per core)
    while this thread reads and tallies them in order. Rows the reader cannot
    parse (wrong field count, bad quoting) fail the audit naming the first,
    unless ``rejects_path`` is given: they then go there with their reason, the
    rest is audited, and the report counts them (``rejected``); with
    ``strict_rejects`` any such row is still an error and nothing is written.
    ``consistency`` (a :class:`hpe_cli.pipelines.audit.consistency.Settings`) adds its checks (JSON, ``output``, ``suspects``).
    """

    from ...io import ANGLE_COLS, MATRIX_COLS, check_output, label_mode, write_json
    from ...io.writers import check_report_outputs
    from ...report.plots import AngleHistograms, plot_files, write_plots
    from ...rotation.audit import CHECKS

    check_report_outputs(report, output, overwrite)
    if plots:
        from pathlib import Path

        if Path(plots).exists():
            for p in plot_files(plots).values():
                check_output(p, overwrite)

    src = _source(input_path, batch_size)
    from ...io import Rejects
    from ...io.system_meta import resolve_system

    rejected = Rejects(rejects_path, overwrite, strict=strict_rejects, source=src)
    if suspects:
        check_output(suspects, overwrite)
    resolved = resolve_system(src, system, default="300w_lp")
    system = resolved.system
    columns = src.columns
    mode = label_mode(columns, src.path, system) if use == "auto" else use
    need = ANGLE_COLS if mode == "angles" else MATRIX_COLS
    # the system's own columns (rotvec, quaternion, 6-D, 4x4, named angles): read through the system
    via_system = (
        use == "auto"
        and (system.storage_kind != "angles" or bool(system.columns))
        and all(c in columns for c in system.value_columns)
    )
    if via_system:
        need = list(system.value_columns)
    tally = None
    if decoder:
        from ...rotation.decoders import DecoderTally

        tally = DecoderTally(decoder)
    missing = [c for c in need if c not in columns]
    if missing:
        raise HpeError(f"{src.path}: missing column(s) {', '.join(missing)} for --columns {mode}")
    if keys:
        bad = [k for k in keys if k not in columns]
        if bad:
            raise HpeError(
                f"{src.path}: --key column(s) {', '.join(bad)} not in the table; "
                f"expected some of: {', '.join(columns[:20])}"
            )
        key_cols = list(dict.fromkeys(keys))
    else:
        key_cols = [c for c in ID_COLUMNS if c in columns]
    id_cols = [c for c in ("file", "image", "image_id", "id", "path") if c in columns][:1]
    if progress is not None and src.num_rows:
        progress.total = src.num_rows
    cons = None
    if consistency is not None:
        from .consistency import ConsistencyAudit, canonical_labels

        cons = ConsistencyAudit(src, consistency)

    hist = AngleHistograms() if plots else None
    examples = {c: [] for c in CHECKS}
    counts = {c: 0 for c in CHECKS}
    flagged = near_not_locked = 0
    from ..pools import default_threads

    workers = default_threads(workers)  # --threads; one per core by default
    dups = _Duplicates()
    flag_bits = []  # one bit a row: flagged by a check other than duplicates
    unread_examples = []
    rows = 0
    read_mode = mode if mode in ("angles", "matrix") else "matrix"

    def work(batch):  # on a worker thread: numpy and Arrow release the GIL
        cols, eff = _system_cols(batch, system, mode, radians, via_system)
        res = _checks(cols, eff, system, near_tol_deg)
        any_flag = np.zeros(batch.num_rows, dtype=bool)
        for c in CHECKS[:-1]:
            any_flag |= res[c]
        cons_in = None if cons is None else (A := canonical_labels(system, cols, eff, res), cons.measure(batch, A))
        return eff, cols, res, any_flag, key_hashes(cols, batch, key_cols), cons_in

    def finish(batch, lines, unread, future):
        nonlocal rows, flagged, near_not_locked, unread_examples
        if unread:  # rows with a non-numeric label value: non_finite, as when read from a text column
            rows += len(unread)
            counts["non_finite"] += len(unread)
            flagged += len(unread)
            unread_examples += [{"row": r.line, "raw": r.raw} for r in unread[:n_examples]]
        eff, cols, res, any_flag, hashes, cons_in = future.result()
        if cons is not None:
            cons.add(batch, lines, *cons_in, unread=len(unread))
        if tally is not None:
            values = np.stack(cols, axis=-1)
            tally.add(system.to_canonical(system.from_angles(values) if eff == "angles" else values.reshape(-1, 3, 3)))
        for c in CHECKS[:-1]:
            m = res[c]
            counts[c] += int(np.count_nonzero(m))
            want = n_examples - len(examples[c])
            if want > 0 and m.any():
                for i in np.flatnonzero(m)[:want]:
                    examples[c].append(_example(batch, int(i), lines[i], id_cols, cols, eff))
        flagged += int(np.count_nonzero(any_flag))
        flag_bits.append(np.packbits(any_flag))
        near_not_locked += int(np.count_nonzero(res["near_gimbal"] & ~res["gimbal_lock"]))
        dups.add(hashes, lines)
        if hist is not None:
            hist.add(np.stack(cols, axis=-1) if eff == "angles" else res["primary"])
        rows += batch.num_rows
        if progress is not None:
            progress.update(batch.num_rows)

    in_order(_batches(src, read_mode, src.path, rejected), work, finish, workers)
    rejected.check()  # with --strict: any set-aside row is an error and nothing is written

    counts["duplicates"] = dups.finish()
    if counts["duplicates"]:
        # duplicates with no other flag add to "flagged"
        bits = _unpack_rows(flag_bits, dups.batch_sizes, dups.dup_idx)
        flagged += int(np.count_nonzero(~bits))
    if unread_examples:
        examples["non_finite"] = sorted(examples["non_finite"] + unread_examples, key=lambda e: e["row"])[:n_examples]
    examples["duplicates"] = [
        {"row": int(a), "same_as": int(b)}
        for a, b in zip(dups.line_of(dups.dup_idx[:n_examples]), dups.line_of(dups.first_idx[:n_examples]))
    ]

    result = {
        "rows": rows,
        **counts,
        "rejected": len(rejected),
        "system": system.name,
        "system_origin": resolved.origin,
        "input": str(src.path),
        "label_columns": mode,
        "units": "radians" if (radians and mode == "angles") else ("degrees" if mode == "angles" else None),
        "settings": {
            "near_gimbal_deg": near_tol_deg,
            "gimbal_lock_tol": system.gimbal_tol,
            "lock_distance": "|cos| (or |sin| for proper Euler) of the middle angle",
            "duplicate_key": (list(need) + key_cols),
        },
        "details": {"flagged": flagged, "near_gimbal_not_locked": near_not_locked},
        "examples": examples,
    }
    if tally is not None:
        result["decoder"] = tally.result()
    if cons is not None:
        from .consistency import consistency_outputs

        reread = lambda: (
            b for b, _, _ in _batches(_source(input_path, batch_size), read_mode, src.path, _SKIP_REJECTS)
        )  # noqa: E731
        result["consistency"] = consistency_outputs(cons, reread, suspects, overwrite, plots, images)

    if output:
        _write_flagged(
            input_path,
            output,
            only_flagged,
            overwrite,
            batch_size,
            system,
            mode,
            radians,
            near_tol_deg,
            dups,
            via_system,
            cons,
        )
    if plots:
        from ..draw_flagged import flagged_pictures

        # the first flagged rows of each check, drawn on their images, for the page
        pics = flagged_pictures(src.path, examples, plots, system, images=images, radians=radians, overwrite=overwrite)
        write_plots(
            hist,
            plots,
            system,
            {
                "input": str(src.path),
                "system": system.name,
                "rows": rows,
                **counts,
                "flagged": result["details"]["flagged"],
            },
            title=f"hpe audit: {src.path.name}",
            overwrite=overwrite,
            pictures=pics,
        )
    rejected.write()
    if report == "-":
        from ...io.writers import json_text

        (echo or print)(json_text(result))
    elif report:
        write_json(result, report, overwrite=overwrite)
    return result


def _unpack_rows(flag_bits, batch_sizes, idx) -> np.ndarray:
    """The stored flag bit of every global row index in ``idx`` (sorted)."""
    out = np.zeros(len(idx), dtype=bool)
    starts = np.concatenate([[0], np.cumsum(batch_sizes)]).astype(np.int64)
    k = np.searchsorted(starts, idx, side="right") - 1
    for b in np.unique(k):
        sel = k == b
        bits = np.unpackbits(flag_bits[b], count=int(batch_sizes[b])).astype(bool)
        out[sel] = bits[idx[sel] - starts[b]]
    return out


def _system_cols(batch, system, mode, radians, via_system):
    """Label columns to check and their mode: a system's own columns (any storage kind) are read through it."""
    if not via_system:
        return _label_cols(batch, mode, radians), mode
    from ...io.labels import label_values

    values = label_values(batch, system, mode, radians)
    return (
        [np.ascontiguousarray(c) for c in values.reshape(len(values), -1).T],
        "angles" if values.ndim == 2 else "matrix",
    )


class _SkipRejects:
    """The second pass skips the rows the first one set aside (already in the rejects file)."""

    path = "-"

    def add(self, *args, **kwargs):
        pass

    def add_unreadable(self, read_rejects):
        pass


_SKIP_REJECTS = _SkipRejects()


def _write_flagged(
    input_path, output, only_flagged, overwrite, batch_size, system, mode, radians, near_tol_deg, dups, via_system, cons
):
    """Second pass over the input: every column, then one boolean column per check and 'flagged'."""
    import pyarrow as pa

    from ...io import TableWriter, system_metadata
    from ...rotation.audit import CHECKS

    names = list(CHECKS) + ["flagged"]
    extra = list(cons.output_columns) if cons is not None else []  # --consistency columns
    src = _source(input_path, batch_size)
    keep = [c for c in src.columns if c not in names + extra]
    meta = {**system_metadata(system), "hpe:audit_of": str(src.path)}
    offset = 0
    with TableWriter(output, overwrite, meta) as w:
        for batch, _, _ in _batches(src, mode, src.path, _SKIP_REJECTS):
            n = batch.num_rows
            res = _checks(*_system_cols(batch, system, mode, radians, via_system), system, near_tol_deg)
            res["duplicates"] = dups.mask(offset, offset + n)
            any_flag = np.zeros(n, dtype=bool)
            for c in CHECKS:
                any_flag |= res[c]
            arrays = list(batch.select(keep).columns) + [pa.array(res[c]) for c in CHECKS] + [pa.array(any_flag)]
            if cons is not None:
                arrays += [pa.array(v) for v in cons.columns(offset, n).values()]
            out = pa.RecordBatch.from_arrays(arrays, names=keep + names + extra)
            if only_flagged:
                out = out.filter(pa.array(any_flag))
            if out.num_rows or w.rows == 0:
                w.write(out)
            offset += n
        if offset == 0:
            more = [pa.field(c, t) for c, t in cons.output_types().items()] if cons is not None else []
            empty = pa.schema([src.schema.field(c) for c in keep] + [pa.field(c, pa.bool_()) for c in names] + more)
            w.write(empty.empty_table())
