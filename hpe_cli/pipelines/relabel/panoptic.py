"""``hpe relabel-panoptic``: CMU Panoptic relabelling as a streaming job (SPEC §6).

The job is split by concept: :mod:`.plan` (:func:`~.plan.plan`: the calibration, the cameras and the frames;
:func:`~.plan.process_chunk`: one chunk of frames -> labelled and rejected views, pure), :mod:`.stats` (counts
and the summary), :mod:`.units` (units, their part files, the ``--resume`` fingerprint, ``--min-change``) and
this module, which runs the job (:func:`run_relabel_panoptic`) and writes the outputs (:func:`write_outputs`).
Memory stays bounded by a few chunks whatever the sequence length.
"""

from __future__ import annotations

import json
import os
import shutil
from collections import deque
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from ...io import TableWriter, arrow_table, system_metadata
from ...io.coco import CocoWriter, annotations_text
from ...io.rejects import rejects_rule
from ...io.transaction import critical, current, note_input
from ...io.whenet_txt import WhenetWriter, whenet_text
from ..parts import record_temps, unlock_parts
from ..pools import borrow, in_order, unit_pool
from .options import RelabelPanopticOptions
from .plan import SAMPLING_REASONS, Config, Plan, plan_many
from .stats import Stats, unit_stats
from .units import (
    MinChange,
    check_done,
    compute,
    make_units,
    prepare_unit_parts,
    read_part,
    reject_schema,
    run_unit,
    unit_task,
    write_part,
)

#: what a unit imports on its first run: local workers import it as they start, while the parent prepares the
#: job (a unit builds its Arrow arrays from numpy buffers, so pandas, 0.3 s to import, is never needed)
WORKER_IMPORTS = ("pyarrow.compute", "pyarrow.ipc", "hpe_cli.io", "hpe_cli.io.coco", "orjson")


@dataclass
class PanopticRun:
    """What :func:`run_relabel_panoptic` did: the plans, the counts per sequence and in total."""

    plans: list
    stats: Stats
    per_sequence: list
    output: object
    options: RelabelPanopticOptions

    def plan_lines(self) -> list:
        """One line per sequence: its calibration, cameras, frames and units (``--verbose``)."""
        return [
            f"{p.sequence}: calibration {p.calibration} ({len(p.cameras)} cameras: "
            f"{', '.join(p.cameras.names[:6])}{' ...' if len(p.cameras) > 6 else ''}); "
            f"frames: {len(p.frames)} selected of {p.available} face files, {len(p.chunks)} units"
            for p in self.plans
        ]

    def summary(self) -> list:
        """The summary lines: per sequence, and the total when there are several."""
        cfg, rejects = self.options.config(), self.options.rejects
        lines = []
        for p, st in zip(self.plans, self.per_sequence):
            lines += st.summary(p, cfg, self.output, rejects)
        if len(self.plans) > 1:
            title = f"total over {len(self.plans)} sequences"
            lines += self.stats.summary(None, cfg, self.output, rejects, n_cameras="N", title=title)
        return lines


def run_relabel_panoptic(seq_dirs, output, opts: RelabelPanopticOptions, *, progress=None) -> PanopticRun:
    """Relabel the Panoptic sequences ``seq_dirs`` (each a sequence, or a folder of sequences) into
    ``output``; ``progress(total=frames)``, if given, makes the progress bar. Returns a :class:`PanopticRun`.

    With ``opts.strict`` any face or view not labelled fails the run (nothing is committed), except those of
    the sampling rules asked for (:data:`~.plan.SAMPLING_REASONS`).
    """
    # the workers start (and import what a unit needs) while the sequences are planned
    with worker_pool(opts.workers, opts.scheduler, opts.resume) as pool:
        plans = plan_many(seq_dirs, opts.calibration, opts.cameras, opts.every, opts.frames)
        for p in plans:  # no output may replace a file the run reads
            for path in {str(p.calibration), *(f.path for f in p.frames.values())}:
                note_input(path)
        total = sum(len(p.frames) + sum(map(len, p.skipped)) for p in plans)
        bar = progress(total=total) if progress is not None else None
        per_seq: list = []
        try:
            stats = write_outputs(plans, output, opts, bar=bar, per_sequence=per_seq, pool=pool)
        finally:
            if bar is not None:
                bar.close()
    if opts.strict:
        strict_rule(stats)
    return PanopticRun(plans, stats, per_seq, output, opts)


def strict_rule(stats: Stats) -> None:
    """``--strict``: any face or view not labelled fails the run, except by the sampling rules asked for."""
    faces = {r: n for r, n in stats.face_reasons.items() if r not in SAMPLING_REASONS and n}
    views = {r: n for r, n in stats.view_reasons.items() if r not in SAMPLING_REASONS and n}
    first = next(iter(faces or views), None)
    rejects_rule(sum(views.values()) + sum(faces.values()), first, has_file=True, strict=True)


def run(p: Plan, cfg: Config, workers: int = 1):
    """Yield :func:`~.plan.process_chunk` results for every chunk of ``p``, in order
    (in memory; :func:`write_outputs` uses parts instead)."""
    tasks = [unit_task([p], cfg, (0, ci), None) for ci in range(len(p.chunks))]
    if workers <= 1 or len(p.chunks) <= 1:
        for task in tasks:
            yield compute(task)
        return
    with unit_pool(workers, warm=WORKER_IMPORTS) as pool:
        yield from in_order(pool, compute, tasks)


def format_unit(task: dict) -> int:
    """Format one unit's labels part as output text (COCO annotations or WHENet lines) into its text part,
    by an atomic rename; return the number of rows. Ids come with the task (the parent assigns them in order),
    so the text is the bytes the streaming writer makes for these rows."""
    t = read_part(task["labels"])
    if task["fmt"] == "coco":
        text = annotations_text(t, task["image_ids"], task["first_id"], path=task["path"], offset=task["offset"])
    else:
        text = whenet_text(t, task["path"], task["offset"])
    tmp = task["text"] + ".tmp"
    with open(tmp, "wb") as fh:
        fh.write(text)
    os.replace(tmp, task["text"])
    return t.num_rows


def relabel_metadata(plans: list, cfg: Config) -> dict:
    """The output's metadata: the system's, and ``hpe:relabel`` (sequences, calibrations, cameras, options)."""
    relabel = {"source": "cmu_panoptic"}
    if len(plans) == 1:
        relabel.update(
            sequence=plans[0].sequence,
            calibration=str(plans[0].calibration),
            cameras=list(map(str, plans[0].cameras.names)),
        )
    else:
        relabel.update(
            sequences=[q.sequence for q in plans],
            calibrations=[str(q.calibration) for q in plans],
            cameras=[list(map(str, q.cameras.names)) for q in plans],
        )
    relabel.update(
        {
            "preset": cfg.preset,
            "max_rmse": cfg.max_rmse if cfg.max_rmse is not None and np.isfinite(cfg.max_rmse) else None,
            "legacy_whenet": cfg.legacy,
            "label": "A = E @ R_cam @ R_head, E = diag(1, -1, -1)",
        }
    )
    if cfg.frame == "crop":
        relabel["label"] = "A = E @ Q.T @ R_cam @ R_head, Q: optical axis -> ray to the head centre (SPEC 10)"
    if cfg.all_views:
        relabel["all_views"] = cfg.all_views
    if cfg.min_change:
        relabel["min_change"] = cfg.min_change
    return {**system_metadata(cfg.system), "hpe:relabel": json.dumps(relabel)}


def write_outputs(plans, output, opts: RelabelPanopticOptions, *, bar=None, per_sequence=None, pool=None) -> Stats:
    """Run the job and write its outputs atomically; return the total :class:`~.stats.Stats`.

    ``plans`` is one :class:`~.plan.Plan` or a list of them (several sequences). The work is split into units
    (sequence x chunk of frames). With one worker, no ``opts.scheduler`` and no ``opts.resume`` the units run
    here and stream to the writers. Otherwise each unit runs in a worker (``opts.workers`` local processes, or
    a Dask cluster at ``opts.scheduler``, ``"local"`` for a ``LocalCluster``), writes its own part files next to
    the output, and returns only its counts; the parts are appended to the outputs in unit order (and removed
    as they are, unless ``resume``), so the output is the same bytes whoever computed it. ``resume`` keeps the
    parts of an interrupted run (same inputs and options) and computes only the missing units.

    ``opts.fmt`` is ``table`` (streamed to Parquet/CSV), ``coco`` or ``whenet`` (streamed by
    :class:`hpe_cli.io.coco.CocoWriter` / :class:`hpe_cli.io.whenet_txt.WhenetWriter`). With workers, text is
    made by the workers too: once a unit is computed, this process gives its rows their ids (in order: image
    ids by first appearance, annotation ids by row) and submits a second task, :func:`format_unit`, that
    writes the unit's text part; the parts are appended to the output in order (copied by the kernel), so the
    heavy float formatting runs in parallel and the bytes are those of the one-process run. The rejects table
    (``opts.rejects``) is streamed too.

    ``bar`` is updated with the frames done; ``per_sequence``, if a list, receives one
    :class:`~.stats.Stats` per sequence. ``pool``, if given, is a running :func:`worker_pool` for the same
    options (started before planning, so its workers are ready when the first unit is); by default the job
    starts its own.
    """
    plans = plans if isinstance(plans, (list, tuple)) else [plans]
    cfg = opts.config()
    parts = _open_parts(plans, cfg, output, opts) if opts.uses_parts else None
    try:
        with ExitStack() as stack:
            # the pool first: its workers start (and import what a unit needs) while the writers are set up
            pool = stack.enter_context(
                borrow(pool) if pool is not None else worker_pool(opts.workers, opts.scheduler, opts.resume)
            )
            meta = relabel_metadata(plans, cfg)
            if opts.fmt == "table":
                out = stack.enter_context(TableWriter(output, opts.overwrite, meta))
            else:
                out = stack.enter_context(text_writer(opts.fmt, output, opts.overwrite, meta.get("hpe:system")))
            rej = stack.enter_context(TableWriter(opts.rejects, opts.overwrite)) if opts.rejects else None
            if parts is not None and current() is not None:  # a run killed from now on leaves these
                record_temps(parts, current().staged_temps())
            sink = _Sink(plans, output, opts, pool, (out, rej))
            units = make_units(plans)
            tasks = [unit_task(plans, cfg, u, parts) for u in units]
            for (si, _), task, result in zip(units, tasks, _unit_results(tasks, cfg, pool, opts)):
                sink.add(si, task, *result)
                if bar is not None:
                    bar.update(result[0]["frames"])
            sink.finish()
    except BaseException:
        # an interrupted run keeps its parts only when it was asked to be resumable (--resume);
        # otherwise nothing of it is left behind (the output transaction's promise)
        if parts is not None and not opts.resume:
            shutil.rmtree(parts, ignore_errors=True)
        if parts is not None:
            unlock_parts(parts)
        raise
    if parts is not None:
        shutil.rmtree(parts, ignore_errors=True)
        unlock_parts(parts)
    total = Stats()
    for st in sink.seq_stats:
        total.merge(st)
    if per_sequence is not None:
        per_sequence.extend(sink.seq_stats)
    return total


def _open_parts(plans: list, cfg: Config, output, opts: RelabelPanopticOptions) -> Path:
    """The run's locked parts folder; removed by the output transaction whatever ends the run (unless
    ``resume``)."""
    with critical():  # a signal waits until `parts` is known and registered for cleanup
        parts = prepare_unit_parts(plans, cfg, opts.fmt, output, opts.resume, opts.overwrite)
        if not opts.resume and current() is not None:
            current().on_abort(lambda: shutil.rmtree(parts, ignore_errors=True))  # whatever ends the run
    return parts


def _unit_results(tasks: list, cfg: Config, pool, opts: RelabelPanopticOptions):
    """``(counts, labels table, rejects table)`` of every unit, in order: computed here, or by the pool's
    workers into part files (only the units without a finished part with ``resume``)."""
    if not opts.uses_parts:
        rschema = reject_schema()
        for t in tasks:
            res = compute(t)
            yield unit_stats(res, cfg), arrow_table(res["table"]), arrow_table(res["rejects"], rschema)
        return
    if opts.resume:
        check_done(tasks)
    todo = [t for t in tasks if not Path(t["stem"] + ".json").exists()]
    computed = in_order(pool, run_unit, todo)
    need = {t["stem"] for t in todo}
    for t in tasks:
        stem = t["stem"]
        if stem in need:
            next(computed)  # in order: this unit's parts are complete after it
        stats = json.loads(Path(stem + ".json").read_text())
        yield stats, read_part(stem + ".labels.arrow"), read_part(stem + ".rejects.arrow")


class _Sink:
    """The outputs of a run (labels as a table or text, rejects) taking the units in order: applies
    ``--min-change``, counts per sequence, and with text formats on parts hands the formatting to the pool."""

    def __init__(self, plans: list, output, opts: RelabelPanopticOptions, pool, writers: tuple):
        self.output, self.opts, self.pool = output, opts, pool
        self.out, self.rej = writers
        self.seq_stats = [Stats() for _ in plans]
        self.rschema = reject_schema()
        self.mc = MinChange(opts.min_change) if opts.min_change else None
        self.text_parts = opts.uses_parts and opts.fmt != "table"
        self.formatting: deque = deque()  # (future, text part, rows, stem) in output order
        self.registered = 0  # rows given ids so far (text formats on parts)
        self.ahead = 2 * getattr(pool, "workers", 1)

    def add(self, si: int, task: dict, stats: dict, t, r) -> None:
        """One unit's counts, labels ``t`` and rejects ``r`` (Arrow tables), in unit order."""
        self.seq_stats[si].add_unit(stats)
        kept = None
        if self.mc is not None:
            t, moved = self.mc.apply(t, self.rschema)
            if moved is not None:
                self.seq_stats[si].moved("below --min-change", moved.num_rows)
                r = pa.concat_tables([r, moved])
                kept = t
        if self.rej is not None:
            self.rej.write(r)
        if self.text_parts:
            self._format_elsewhere(task["stem"], t, kept)
        else:
            self.out.write(t)
            if self.opts.uses_parts:
                self._drop_parts(task["stem"])

    def _format_elsewhere(self, stem: str, t, kept) -> None:
        """Ids here, in order; the text is made by a worker (:func:`format_unit`)."""
        fmt = self.opts.fmt
        labels = stem + ".labels.arrow"
        if kept is not None:  # --min-change dropped rows: the worker formats what is kept
            labels = stem + ".kept.arrow"
            write_part(labels, kept)
        job = {
            "fmt": fmt,
            "labels": labels,
            "text": f"{stem}.{fmt}.text",
            "path": str(self.output),
            "offset": self.registered,
            "first_id": self.registered + 1,
            "image_ids": self.out.image_ids(t, self.registered) if fmt == "coco" else None,
        }
        self.registered += t.num_rows
        self.formatting.append((self.pool.submit(format_unit, job), job["text"], t.num_rows, stem))
        self._append_formatted(self.ahead)

    def _append_formatted(self, limit: int) -> None:
        """Append the formatted units at the head of the queue: all that are done, and more while over limit."""
        while self.formatting and (len(self.formatting) > limit or self.formatting[0][0].done()):
            fut, text, rows, stem = self.formatting.popleft()
            fut.result()
            self.out.append_file(text, rows)  # opened before it returns: the part can go at once
            Path(text).unlink(missing_ok=True)
            self._drop_parts(stem)

    def _drop_parts(self, stem: str) -> None:
        """A consumed unit's parts, unless they are kept for --resume."""
        if not self.opts.resume:
            for suffix in (".labels.arrow", ".rejects.arrow", ".json", ".kept.arrow"):
                Path(stem + suffix).unlink(missing_ok=True)

    def finish(self) -> None:
        """Append the text parts still under way (text formats on parts)."""
        self._append_formatted(0)


def worker_pool(workers: int = 1, scheduler: str | None = None, resume: bool = False):
    """The pool :func:`write_outputs` runs its units on for these options (a context manager): ``workers``
    local processes, a Dask cluster at ``scheduler``, or this process (one worker, no scheduler, no
    ``resume``). Start it before planning and pass it as ``pool=``: the workers start and import what a
    unit needs meanwhile."""
    use_parts = workers > 1 or scheduler is not None or resume
    return unit_pool(workers if use_parts else 1, scheduler if use_parts else None, warm=WORKER_IMPORTS)


def text_writer(fmt: str, output, overwrite: bool, system=None):
    """The streaming COCO or WHENet writer (flat memory; units formatted elsewhere are appended as files)."""
    if fmt == "coco":
        return CocoWriter(
            output,
            overwrite,
            image_size_cols=("image_width", "image_height"),
            info={"hpe:system": system} if system else None,
        )  # read back by io.system_meta
    return WhenetWriter(output, overwrite)
