"""``hpe audit`` as a streaming job: per-row checks, duplicates, report, plots and a flagged table.

Memory is flat in the number of rows apart from one 64-bit hash per row, kept
twice (duplicates, 16 bytes a row): the checks are counted batch by batch, the label columns are
checked as columns (no ``(N, 3, 3)`` stacks), and the optional ``-o`` table is
written in a second pass that recomputes each batch's flags.

Row numbers in the report are 1-based file lines (header = line 1; for
Parquet, the line the row would have in a CSV with a header).

The steps: :func:`plan_audit` (the label source opened once, which columns to
read), :class:`AuditTally` (each batch checked on a worker thread, tallied in
input order), :func:`report_dict` (the JSON report), :func:`write_outputs`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import HpeError
from ...io import ANGLE_COLS, MATRIX_COLS, Rejects, check_output, open_table, write_json
from ...io.label_source import AUTO, LabelSource, label_source
from ...io.labels import is_native
from ...io.writers import check_report_outputs, json_text
from ...report.plots import AngleHistograms, plot_files, write_plots
from ...rotation.audit import CHECKS
from ...rotation.decoders import DecoderTally
from ..heap import keep_freed_memory
from ..pools import default_threads, run_in_order
from .batches import SKIP_REJECTS, check_batch, read_batches, system_cols
from .common import canonical_labels
from .duplicates import ID_COLUMNS, Duplicates, key_hashes, unpack_rows
from .flagged import write_flagged
from .options import AuditOptions


@dataclass(frozen=True)
class AuditPlan:
    """What one audit reads.

    Attributes
    ----------
    input_path : str or path
        The input as given (re-read by the second passes).
    labels : LabelSource
        The table opened once, its resolved system and label storage.
    mode : str
        The label storage audited: ``"angles"``, ``"matrix"`` or the system's own storage kind.
    via_system : bool
        The labels are the system's own value columns, read through the system.
    need : tuple of str
        The label columns (the first part of the duplicate key).
    key_cols, id_cols : tuple of str
        The other columns of the duplicate key; the column naming a row in the examples.
    """

    input_path: object
    labels: LabelSource
    mode: str
    via_system: bool
    need: tuple
    key_cols: tuple
    id_cols: tuple

    @property
    def system(self):
        return self.labels.system

    @property
    def path(self) -> Path:
        return self.labels.path

    @property
    def read_mode(self) -> str:
        """``"angles"`` or ``"matrix"``: which label columns' non-numeric values the reader lets through."""
        return self.mode if self.mode in ("angles", "matrix") else "matrix"


def plan_audit(input_path, table, system, options: AuditOptions) -> AuditPlan:
    """Resolve the labels' system and storage (:func:`hpe_cli.io.label_source.label_source`) and the key."""
    use = options.use
    if use != AUTO:  # the columns asked for must be there, whatever the system says
        missing = [c for c in (ANGLE_COLS if use == "angles" else MATRIX_COLS) if c not in table.columns]
        if missing:
            raise HpeError(f"{table.path}: missing column(s) {', '.join(missing)} for --columns {use}")
    labels = label_source(table, system, default="300w_lp", mode=use)  # checks the label columns are there
    system, columns, mode = labels.system, labels.columns, labels.mode
    # the system's own columns (rotvec, quaternion, 6-D, 4x4, named angles): read through the system
    via_system = use == AUTO and is_native(system, columns)
    need = tuple(system.value_columns) if via_system else (ANGLE_COLS if mode == "angles" else MATRIX_COLS)
    if options.keys:
        bad = [k for k in options.keys if k not in columns]
        if bad:
            raise HpeError(
                f"{table.path}: --key column(s) {', '.join(bad)} not in the table; "
                f"expected some of: {', '.join(columns[:20])}"
            )
        key_cols = tuple(dict.fromkeys(options.keys))
    else:
        key_cols = tuple(c for c in ID_COLUMNS if c in columns)
    id_cols = tuple(c for c in ("file", "image", "image_id", "id", "path") if c in columns)[:1]
    return AuditPlan(input_path, labels, mode, via_system, tuple(need), key_cols, id_cols)


def example_row(batch, i, line, id_cols, cols, mode) -> dict:
    """One example of the report: its line, id column and label values (non-finite values as text)."""
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


def first_true(m, k: int) -> np.ndarray:
    """The indices of the first ``k`` True values of the boolean array ``m`` (all of them if fewer), reading
    only as far as needed (windows doubling from 4,096 values)."""
    w = 4096
    while True:
        got = np.flatnonzero(m[:w])
        if len(got) >= k or w >= len(m):
            return got[:k]
        w *= 4


def batch_tally(res, n_examples: int, full=frozenset()) -> tuple:
    """What the in-order tally adds of one batch's check masks ``res``, computed where the batch was checked:
    ``(count per check, its first n_examples row indices (none for the checks in full: they have all their
    examples already), packed bits of the rows any check but duplicates flags, their count, the near_gimbal rows
    not locked)``."""
    any_flag = np.zeros(len(res[CHECKS[0]]), dtype=bool)
    counts, firsts = {}, {}
    for c in CHECKS[:-1]:
        m = res[c]
        any_flag |= m
        counts[c] = int(np.count_nonzero(m))
        firsts[c] = first_true(m, n_examples) if counts[c] and n_examples and c not in full else ()
    near_not_locked = int(np.count_nonzero(res["near_gimbal"] & ~res["gimbal_lock"]))
    return counts, firsts, np.packbits(any_flag), int(np.count_nonzero(any_flag)), near_not_locked


def numbered(batches):
    """``((batch, offset of its first row), lines, unread)`` of :func:`read_batches`' items."""
    offset = 0
    for batch, lines, unread in batches:
        yield (batch, offset), lines, unread
        offset += batch.num_rows


class AuditTally:
    """The counts, examples, flags and duplicate hashes of one audit.

    :meth:`work` checks and hashes a batch (on a worker thread: numpy and Arrow
    release the GIL); :meth:`finish` adds its result in input order;
    :meth:`close` finds the duplicates once every batch is in.
    """

    def __init__(self, plan: AuditPlan, options: AuditOptions, cons=None, progress=None):
        self.plan, self.options, self.cons, self.progress = plan, options, cons, progress
        self.decoder = DecoderTally(options.decoder) if options.decoder else None
        self.hist = None
        if options.plots:
            self.hist = AngleHistograms()
        self.examples = {c: [] for c in CHECKS}
        self.counts = {c: 0 for c in CHECKS}
        self.flagged = self.near_not_locked = self.rows = 0
        self.dups = Duplicates(plan.labels.table.num_rows)
        self.flag_bits = []  # one bit a row: flagged by a check other than duplicates
        self.unread_examples = []

    def work(self, item):
        """Check, tally and hash one batch ``(batch, its first row's offset)`` on a worker thread: ``(mode, cols,
        masks, tally, hashes, consistency evidence)``; ``tally`` is :func:`batch_tally`'s, the hashes are written
        to :meth:`Duplicates.slot` when it has room."""
        batch, offset = item
        plan = self.plan
        cols, eff = system_cols(batch, plan.system, plan.mode, self.options.radians, plan.via_system)
        res = check_batch(cols, eff, plan.system, self.options.near_tol_deg, primary=self.hist is not None)
        cons_in = None
        if self.cons is not None:
            A = canonical_labels(plan.system, cols, eff, res)
            cons_in = (A, self.cons.measure(batch, A))
        slot = self.dups.slot(offset, batch.num_rows)
        hashes = key_hashes(cols, batch, plan.key_cols, out=slot)
        if slot is not None:
            self.dups.file(hashes)
        # checks whose examples are all in need none from this batch (examples only grow: a safe hint)
        full = frozenset(c for c, ex in self.examples.items() if len(ex) >= self.options.n_examples)
        return eff, cols, res, batch_tally(res, self.options.n_examples, full), hashes, cons_in

    def finish(self, item, lines, unread, result) -> None:
        """Add one batch's result (in input order)."""
        batch, _ = item
        if unread:  # rows with a non-numeric label value: non_finite, as when read from a text column
            self.rows += len(unread)
            self.counts["non_finite"] += len(unread)
            self.flagged += len(unread)
            self.unread_examples += [{"row": r.line, "raw": r.raw} for r in unread[: self.options.n_examples]]
        eff, cols, res, tally, hashes, cons_in = result
        if self.cons is not None:
            self.cons.add(batch, lines, *cons_in, unread=len(unread))
        if self.decoder is not None:
            system, values = self.plan.system, np.stack(cols, axis=-1)
            stored = system.from_angles(values) if eff == "angles" else values.reshape(-1, 3, 3)
            self.decoder.add(system.to_canonical(stored))
        self._count(batch, lines, cols, eff, tally)
        self.dups.add(hashes, lines)
        if self.hist is not None:
            self.hist.add(np.stack(cols, axis=-1) if eff == "angles" else res["primary"])
        self.rows += batch.num_rows
        if self.progress is not None:
            self.progress.update(batch.num_rows)

    def _count(self, batch, lines, cols, eff, tally) -> None:
        counts, firsts, flag_bits, flagged, near_not_locked = tally
        n_examples = self.options.n_examples
        for c, k in counts.items():
            self.counts[c] += k
            want = n_examples - len(self.examples[c])
            for i in firsts[c][: max(want, 0)]:
                self.examples[c].append(example_row(batch, int(i), lines[i], self.plan.id_cols, cols, eff))
        self.flagged += flagged
        self.flag_bits.append(flag_bits)
        self.near_not_locked += near_not_locked

    def close(self) -> None:
        """Find the duplicates; count those with no other flag as flagged; finish the examples."""
        dups, n_examples = self.dups, self.options.n_examples
        self.counts["duplicates"] = dups.finish(default_threads(self.options.threads))
        if self.counts["duplicates"]:
            bits = unpack_rows(self.flag_bits, dups.batch_sizes, dups.dup_idx)
            self.flagged += int(np.count_nonzero(~bits))
        if self.unread_examples:
            merged = sorted(self.examples["non_finite"] + self.unread_examples, key=lambda e: e["row"])
            self.examples["non_finite"] = merged[:n_examples]
        self.examples["duplicates"] = [
            {"row": int(a), "same_as": int(b)}
            for a, b in zip(dups.line_of(dups.dup_idx[:n_examples]), dups.line_of(dups.first_idx[:n_examples]))
        ]


def report_dict(plan: AuditPlan, options: AuditOptions, tally: AuditTally, rejected: int) -> dict:
    """The JSON report (without ``decoder`` and ``consistency``, added by :func:`run_audit`)."""
    system, mode = plan.system, plan.mode
    return {
        "rows": tally.rows,
        **tally.counts,
        "rejected": rejected,
        "system": system.name,
        "system_origin": plan.labels.resolved.origin,
        "input": str(plan.path),
        "label_columns": mode,
        "units": "radians" if (options.radians and mode == "angles") else ("degrees" if mode == "angles" else None),
        "settings": {
            "near_gimbal_deg": options.near_tol_deg,
            "gimbal_lock_tol": system.gimbal_tol,
            "lock_distance": "|cos| (or |sin| for proper Euler) of the middle angle",
            "duplicate_key": (list(plan.need) + list(plan.key_cols)),
        },
        "details": {"flagged": tally.flagged, "near_gimbal_not_locked": tally.near_not_locked},
        "examples": tally.examples,
    }


def check_outputs(options: AuditOptions) -> None:
    """Refuse existing outputs without ``overwrite`` before anything is read."""
    check_report_outputs(options.report, options.output, options.overwrite)
    if options.plots and Path(options.plots).exists():
        for p in plot_files(options.plots).values():
            check_output(p, options.overwrite)


def write_plots_page(plan: AuditPlan, options: AuditOptions, tally: AuditTally, result: dict) -> None:
    """``--plots``: histograms, the coverage map and the page with the first flagged rows drawn."""
    from ..draw import flagged_pictures  # lazy: OpenCV, only with --plots

    system = plan.system
    pics = flagged_pictures(
        plan.labels,  # the table opened once (re-read for the pictures), its system and label storage
        tally.examples,
        options.plots,
        images=options.images,
        radians=options.radians,
        overwrite=options.overwrite,
    )
    summary = {"input": str(plan.path), "system": system.name, "rows": tally.rows, **tally.counts}
    summary["flagged"] = result["details"]["flagged"]
    write_plots(
        tally.hist,
        options.plots,
        system,
        summary,
        title=f"hpe audit: {plan.path.name}",
        overwrite=options.overwrite,
        pictures=pics,
    )


def write_outputs(plan, options, tally, result, rejected, echo=None) -> None:
    """The flagged table, the plots page, the rejects file and the report, in that order."""
    if options.output:
        write_flagged(plan, options, tally.dups, tally.cons)
    if options.plots:
        write_plots_page(plan, options, tally, result)
    rejected.write()
    if options.report == "-":
        (echo or print)(json_text(result))
    elif options.report:
        write_json(result, options.report, overwrite=options.overwrite)


def run_audit(input_path, system=None, options: AuditOptions | None = None, *, progress=None, echo=None) -> dict:
    """Audit ``input_path`` and write the requested outputs; return the report dict.

    Parameters
    ----------
    input_path : str or path
        Any label table ``hpe`` reads.
    system : RotationSystem, optional
        ``--system``: the labels' system for files that name none (default ``300w_lp``).
    options : AuditOptions, optional
        What to check and write (default: the report only, returned).
    progress : tqdm-like, optional
        Updated with the rows read.
    echo : callable, optional
        Prints the report for ``report="-"`` (default ``print``).

    Notes
    -----
    Batches are checked and hashed on ``options.threads`` threads (default: one per core)
    while this thread reads and tallies them in order. Rows the reader cannot
    parse (wrong field count, bad quoting) fail the audit naming the first,
    unless ``options.rejects`` is given: they then go there with their reason, the
    rest is audited, and the report counts them (``rejected``); with
    ``strict`` any such row is still an error and nothing is written.
    ``options.consistency`` (a :class:`hpe_cli.pipelines.audit.consistency.Settings`) adds its checks (JSON,
    ``output``, ``suspects``).
    """
    o = options if options is not None else AuditOptions()
    check_outputs(o)
    table = open_table(input_path, o.batch_size, with_lines=True)
    rejected = Rejects(o.rejects, o.overwrite, strict=o.strict, source=table)
    if o.suspects:
        check_output(o.suspects, o.overwrite)
    plan = plan_audit(input_path, table, system, o)
    if progress is not None and table.num_rows:
        progress.total = table.num_rows
    cons = None
    if o.consistency is not None:  # its readers and the landmark fit load only for --consistency (start-up)
        from .consistency import ConsistencyAudit  # lazy: the landmark fits load only with --consistency

        cons = ConsistencyAudit(table, o.consistency)
    tally = AuditTally(plan, o, cons, progress)
    keep_freed_memory()  # the batches' freed temporaries reused, not faulted in again (pipelines.heap)
    stream = table
    if table.kind == "parquet" and cons is None:  # its rows' numbers are their offsets: no column of them to make
        stream = open_table(input_path, o.batch_size, with_lines=False)
    run_in_order(
        numbered(read_batches(stream, plan.read_mode, rejected)), tally.work, tally.finish, default_threads(o.threads)
    )
    rejected.check()  # with --strict: any set-aside row is an error and nothing is written
    tally.close()

    result = report_dict(plan, o, tally, len(rejected))
    if tally.decoder is not None:
        result["decoder"] = tally.decoder.result()
    if cons is not None:

        def reread():
            src = open_table(input_path, o.batch_size, with_lines=True)
            return (b for b, _, _ in read_batches(src, plan.read_mode, SKIP_REJECTS))

        from .consistency import consistency_outputs  # lazy: only with --consistency

        result["consistency"] = consistency_outputs(cons, reread, o.suspects, o.overwrite, o.plots, o.images)
    write_outputs(plan, o, tally, result, rejected, echo)
    return result
