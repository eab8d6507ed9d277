"""CMU Panoptic relabelling as a streaming job (SPEC §6).

The job is split in four modules: :mod:`.panoptic_plan` (:func:`plan`: the
calibration, the cameras and the frames; :func:`process_chunk`: one chunk of
frames -> labelled and rejected views, pure), :mod:`.panoptic_stats` (counts
and the summary), :mod:`.panoptic_parts` (units, their part files, the
``--resume`` fingerprint, ``--min-change``) and this one, which writes the
outputs (:func:`write_outputs`) and re-exports the others' public names.
Memory stays bounded by a few chunks whatever the sequence length.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError  # noqa: F401 - re-exported for callers of this module
from .panoptic_parts import (  # noqa: F401
    MinChange,
    _fingerprint,
    _prepare_parts,
    _read_part,
    _reject_schema,
    _write_part,
    check_done,
    compute,
    make_units,
    parts_dir_for,
    record_temps,
    run_unit,
    unit_task,
    unlock_parts,
)
from .panoptic_plan import (  # noqa: F401
    CAMERA_PRESETS,
    CHUNK_FRAMES,
    REJECT_COLS,
    SAMPLING_REASONS,
    SKIPPED,
    WHENET_HAGGLING,
    Config,
    Plan,
    _image_paths,
    find_sequences,
    parse_frames,
    plan,
    plan_many,
    process_chunk,
)
from .panoptic_stats import RmseStats, Stats, unit_stats
from .relabel import LEGACY_COLS, REASONS


def run(p: Plan, cfg: Config, workers: int = 1):
    """Yield :func:`process_chunk` results for every chunk of ``p``, in order
    (in memory; :func:`write_outputs` uses parts instead)."""
    tasks = [unit_task([p], cfg, (0, ci), None) for ci in range(len(p.chunks))]
    if workers <= 1 or len(p.chunks) <= 1:
        for task in tasks:
            yield compute(task)
        return
    from .pools import in_order, unit_pool

    with unit_pool(workers, warm=WORKER_IMPORTS) as pool:
        yield from in_order(pool, compute, tasks)


def format_unit(task: dict) -> int:
    """Format one unit's labels part as output text (COCO annotations or WHENet lines) into its text part,
    by an atomic rename; return the number of rows. Ids come with the task (the parent assigns them in order),
    so the text is the bytes the streaming writer makes for these rows."""
    import os

    t = _read_part(task["labels"])
    if task["fmt"] == "coco":
        from ..io.coco import annotations_text

        text = annotations_text(t, task["image_ids"], task["first_id"], path=task["path"], offset=task["offset"])
    else:
        from ..io.whenet_txt import whenet_text

        text = whenet_text(t, task["path"], task["offset"])
    tmp = task["text"] + ".tmp"
    with open(tmp, "wb") as fh:
        fh.write(text)
    os.replace(tmp, task["text"])
    return t.num_rows


def write_outputs(
    p,
    cfg: Config,
    output,
    fmt: str = "table",
    rejects_path=None,
    overwrite: bool = False,
    workers: int = 1,
    bar=None,
    *,
    scheduler: str | None = None,
    resume: bool = False,
    per_sequence: list | None = None,
    pool=None,
) -> Stats:
    """Run the job and write its outputs atomically; return the total :class:`Stats`.

    ``p`` is one :class:`Plan` or a list of them (several sequences). The
    work is split into units (sequence x chunk of frames). With one worker,
    no ``scheduler`` and no ``resume`` the units run here and stream to the
    writers. Otherwise each unit runs in a worker (``workers`` local
    processes, or a Dask cluster at ``scheduler``, ``"local"`` for a
    ``LocalCluster``), writes its own part files next to the output, and
    returns only its counts; the parts are appended to the outputs in unit
    order (and removed as they are, unless ``resume``), so the output is
    the same bytes whoever computed it. ``resume`` keeps the parts of an
    interrupted run (same inputs and options) and computes only the missing
    units.

    ``fmt`` is ``table`` (streamed to Parquet/CSV), ``coco`` or ``whenet``
    (streamed by :class:`hpe_cli.io.coco.CocoWriter` /
    :class:`hpe_cli.io.whenet_txt.WhenetWriter`). With workers, text is
    made by the workers too: once a unit is computed, this process gives its
    rows their ids (in order: image ids by first appearance, annotation ids
    by row) and submits a second task, :func:`format_unit`, that writes the
    unit's text part; the parts are appended to the output in order (copied
    by the kernel), so the heavy float formatting runs in parallel and the
    bytes are those of the one-process run. The rejects table is streamed
    too.
    ``per_sequence``, if a list, receives one :class:`Stats` per sequence.
    ``pool``, if given, is a running :func:`worker_pool` for the same
    ``workers``, ``scheduler`` and ``resume`` (started before planning, so
    its workers are ready when the first unit is); by default the job starts
    its own.
    """
    import json
    import shutil
    from collections import deque
    from contextlib import ExitStack

    from ..io import TableWriter, arrow_table, system_metadata
    from ..rotation import get_system

    plans = p if isinstance(p, (list, tuple)) else [p]
    system = get_system(cfg.system)
    seq_stats = [Stats() for _ in plans]
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
    for k in ("all_views", "min_change"):
        if getattr(cfg, k):
            relabel[k] = getattr(cfg, k)
    meta = {**system_metadata(system), "hpe:relabel": json.dumps(relabel)}
    rschema = _reject_schema()
    units = make_units(plans)
    use_parts = workers > 1 or scheduler is not None or resume
    from ..io.transaction import critical, current

    parts = None
    with critical():  # a signal waits until `parts` is known and registered for cleanup
        parts = _prepare_parts(plans, cfg, fmt, output, resume, overwrite) if use_parts else None
        if parts is not None and not resume and current() is not None:
            current().on_abort(lambda: shutil.rmtree(parts, ignore_errors=True))  # whatever ends the run
    tasks = [unit_task(plans, cfg, u, parts) for u in units]
    mc = MinChange(cfg.min_change) if cfg.min_change else None

    def results(pool):
        if not use_parts:
            for t in tasks:
                res = compute(t)
                yield unit_stats(res, cfg), arrow_table(res["table"]), arrow_table(res["rejects"], rschema)
            return
        from .pools import in_order

        if resume:
            check_done(tasks)
        todo = [t for t in tasks if not Path(t["stem"] + ".json").exists()]
        computed = in_order(pool, run_unit, todo)
        need = {t["stem"] for t in todo}
        for t in tasks:
            stem = t["stem"]
            if stem in need:
                next(computed)  # in order: this unit's parts are complete after it
            stats = json.loads(Path(stem + ".json").read_text())
            yield stats, _read_part(stem + ".labels.arrow"), _read_part(stem + ".rejects.arrow")

    def drop_parts(stem):  # a consumed unit's parts, unless they are kept for --resume
        if not resume:
            for suffix in (".labels.arrow", ".rejects.arrow", ".json", ".kept.arrow"):
                Path(stem + suffix).unlink(missing_ok=True)

    text_parts = use_parts and fmt != "table"
    formatting: deque = deque()  # (future, text part, rows, stem) in output order

    def append_formatted(limit):
        """Append the formatted units at the head of the queue: all that are done, and more while over limit."""
        while formatting and (len(formatting) > limit or formatting[0][0].done()):
            fut, text, rows, stem = formatting.popleft()
            fut.result()
            out.append_file(text, rows)  # opened before it returns: the part can go at once
            Path(text).unlink(missing_ok=True)
            drop_parts(stem)

    from .pools import borrow

    try:
        with ExitStack() as stack:
            # the pool first: its workers start (and import what a unit needs) while the writers are set up
            pool = stack.enter_context(borrow(pool) if pool is not None else worker_pool(workers, scheduler, resume))
            if fmt == "table":
                out = stack.enter_context(TableWriter(output, overwrite, meta))
            else:
                out = stack.enter_context(_text_writer(fmt, output, overwrite, meta.get("hpe:system")))
            rej = stack.enter_context(TableWriter(rejects_path, overwrite)) if rejects_path else None
            if parts is not None and current() is not None:  # a run killed from now on leaves these
                record_temps(parts, current().staged_temps())
            ahead = 2 * getattr(pool, "workers", 1)
            registered = 0  # rows given ids so far (text formats on parts)
            for (si, _), task, (stats, t, r) in zip(units, tasks, results(pool)):
                seq_stats[si].add_unit(stats)
                kept = None
                if mc is not None:
                    t, moved = mc.apply(t, rschema)
                    if moved is not None:
                        seq_stats[si].moved("below --min-change", moved.num_rows)
                        import pyarrow as pa

                        r = pa.concat_tables([r, moved])
                        kept = t
                if rej is not None:
                    rej.write(r)
                if text_parts:  # ids here, in order; the text is made by a worker
                    stem = task["stem"]
                    labels = stem + ".labels.arrow"
                    if kept is not None:  # --min-change dropped rows: the worker formats what is kept
                        labels = stem + ".kept.arrow"
                        _write_part(labels, kept)
                    job2 = {
                        "fmt": fmt,
                        "labels": labels,
                        "text": f"{stem}.{fmt}.text",
                        "path": str(output),
                        "offset": registered,
                        "first_id": registered + 1,
                        "image_ids": out.image_ids(t, registered) if fmt == "coco" else None,
                    }
                    registered += t.num_rows
                    formatting.append((pool.submit(format_unit, job2), job2["text"], t.num_rows, stem))
                    append_formatted(ahead)
                else:
                    out.write(t)
                    if use_parts:
                        drop_parts(task["stem"])
                if bar is not None:
                    bar.update(stats["frames"])
            append_formatted(0)
    except BaseException:
        # an interrupted run keeps its parts only when it was asked to be resumable (--resume);
        # otherwise nothing of it is left behind (the output transaction's promise)
        if parts is not None and not resume:
            shutil.rmtree(parts, ignore_errors=True)
        if parts is not None:
            unlock_parts(parts)
        raise
    if parts is not None:
        shutil.rmtree(parts, ignore_errors=True)
        unlock_parts(parts)
    total = Stats()
    for st in seq_stats:
        total.merge(st)
    if per_sequence is not None:
        per_sequence.extend(seq_stats)
    return total


#: what a unit imports on its first run: local workers import it as they start, while the parent prepares the
#: job (a unit builds its Arrow arrays from numpy buffers, so pandas, 0.3 s to import, is never needed)
WORKER_IMPORTS = ("pyarrow.compute", "pyarrow.ipc", "hpe_cli.io", "hpe_cli.io.coco", "orjson")


def worker_pool(workers: int = 1, scheduler: str | None = None, resume: bool = False):
    """The pool :func:`write_outputs` runs its units on for these options (a context manager): ``workers``
    local processes, a Dask cluster at ``scheduler``, or this process (one worker, no scheduler, no
    ``resume``). Start it before planning and pass it as ``pool=``: the workers start and import what a
    unit needs meanwhile."""
    from .pools import unit_pool

    use_parts = workers > 1 or scheduler is not None or resume
    return unit_pool(workers if use_parts else 1, scheduler if use_parts else None, warm=WORKER_IMPORTS)


def _text_writer(fmt: str, output, overwrite: bool, system=None):
    """The streaming COCO or WHENet writer (flat memory; units formatted elsewhere are appended as files)."""
    if fmt == "coco":
        from ..io.coco import CocoWriter

        return CocoWriter(
            output,
            overwrite,
            image_size_cols=("image_width", "image_height"),
            info={"hpe:system": system} if system else None,
        )  # read back by io.system_meta
    from ..io.whenet_txt import WhenetWriter

    return WhenetWriter(output, overwrite)


__all__ = [
    "CAMERA_PRESETS",
    "CHUNK_FRAMES",
    "LEGACY_COLS",
    "REASONS",
    "REJECT_COLS",
    "WHENET_HAGGLING",
    "Config",
    "MinChange",
    "Plan",
    "RmseStats",
    "Stats",
    "find_sequences",
    "format_unit",
    "parse_frames",
    "parts_dir_for",
    "plan",
    "plan_many",
    "process_chunk",
    "run",
    "run_unit",
    "worker_pool",
    "write_outputs",
]
