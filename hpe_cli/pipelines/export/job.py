"""``hpe export`` as one job: load inputs -> select/split -> place pixels -> write layout."""

from __future__ import annotations

import shutil
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from ...errors import HpeError
from ...io import Rejects
from ...io.export import get_layout
from ...io.transaction import critical, current
from ...rotation.systems import canonical_system, get_system
from ..parts import prepare_parts, record_temps, unlock_parts
from ..pools import unit_pool
from . import pixels, write
from .inputs import load_inputs
from .options import ExportOptions
from .select import select
from .units import HOW_COMPARED, WORKER_IMPORTS, fingerprint, make_units


def _check_output(inputs, output: Path, opts) -> None:
    if output.exists() and not opts.overwrite:
        raise HpeError(f"{output}: already exists (use --overwrite to replace it)")
    for p in inputs:
        try:
            if Path(p).resolve() == output.resolve() or output.resolve() in Path(p).resolve().parents:
                raise HpeError(f"{output}: is an input (or holds one); choose another output folder")
        except OSError:
            pass


def _layout_and_system(opts):

    try:
        layout = get_layout(opts.layout, system=opts.system, form=opts.form, trainer=opts.trainer)
    except ValueError as exc:
        raise HpeError(str(exc)) from None
    chosen = None if opts.system is None else get_system(opts.system)
    if layout.system is not None and chosen is not None and chosen.name != layout.system:
        raise HpeError(
            f"--layout {layout.name} stores labels in the {layout.system} system, which its trainer "
            f"expects; --system {chosen.name} cannot be used with it"
        )
    if layout.system is not None:
        return layout, get_system(layout.system)
    return layout, chosen or canonical_system()


def run_export(inputs, output, opts: ExportOptions, progress=None) -> dict:
    """Export ``inputs`` to the folder ``output`` (see the package docstring). Returns the summary dict.

    The pixels are made in units (:mod:`.units`) on ``opts.workers`` local processes, or on a Dask cluster
    (``opts.scheduler``: an address, or ``"local"`` for a ``LocalCluster`` of ``opts.workers`` processes);
    with a scheduler or ``opts.resume`` the units keep their parts next to the output
    (``.OUT.hpe-parts/``) until the run commits, and ``opts.resume`` continues an interrupted run. Every
    runner gives the same bytes.
    """

    output = Path(output)
    _check_output(inputs, output, opts)
    use_parts = opts.scheduler is not None or opts.resume
    with ExitStack() as stack:
        # the workers start (and import what a unit needs) while the labels are read and selected
        pool = stack.enter_context(
            unit_pool(opts.workers if opts.workers > 1 or use_parts else 1, opts.scheduler, warm=WORKER_IMPORTS)
        )
        return _run(inputs, output, opts, progress, pool, use_parts)


def _run(inputs, output: Path, opts, progress, pool, use_parts: bool) -> dict:

    rejects = Rejects(opts.rejects, opts.overwrite)
    layout, system = _layout_and_system(opts)
    # stage 1 and 2: the label table, the layout's rules, splits and sampling
    rows = load_inputs(inputs, opts.images, opts.input_system, landmarks=layout.uses_landmarks, radians=opts.radians)
    sel = select(rows, layout, system, opts)
    # stage 3: crop geometry, one task per source image, cut into units
    plan = pixels.plan_crops(sel, layout, opts)
    todo = np.flatnonzero(sel.reasons == "")
    if todo.size == 0:
        write.fail_nothing_left(
            rejects,
            sel,
            write.nothing_left(layout, sel.reasons, np.arange(sel.n), "every label is rejected"),
            opts.strict,
        )
    pixels.name_files(sel, layout, plan, todo)
    units = make_units(pixels.build_tasks(sel, layout, plan, todo))
    splits_used = sorted(set(sel.split[todo].tolist()))
    try:
        layout.check_splits(splits_used)
    except ValueError as exc:
        raise HpeError(str(exc)) from None
    final_root = output.resolve()
    parts = None
    try:
        with write.staged_dir(output, opts.overwrite) as stage:
            from ...io.transaction import current

            layout.open(stage, splits_used)
            cfg = pixels.worker_config(stage, layout, splits_used, opts)
            cfg["shown"] = str(final_root)  # the path a user sees in a message (a full disk)
            if use_parts:
                parts = _parts(output, opts, units, cfg, inputs)
                if current() is not None:  # a run killed from now on leaves these
                    record_temps(parts, current().staged_temps())
            bar = progress(total=int(todo.size)) if progress else None
            try:
                results = pixels.unit_results(units, cfg, pool, parts, opts.resume)
                px = pixels.run_tasks(results, sel, layout, plan, stage, bar, keep_parts=parts is not None)
                img_rej = px.status != ""
                sel.reasons[img_rej] = px.status[img_rej]
                # stage 4: the layout's index files, the summary, the rejects
                try:
                    exported, notes_extra = write.write_index(stage, layout, sel, plan, px, todo, system, final_root)
                except write.NothingLeft as exc:  # every image unreadable: the rejects file still says why
                    write.fail_nothing_left(rejects, sel, exc, opts.strict)
            except BaseException:
                layout.abort()
                raise
            finally:
                if bar is not None:
                    bar.close()
            summary = write.summary_of(layout, system, inputs, sel, plan, exported, notes_extra, opts)
            write.write_summary(stage, summary)
            write.write_rejects(rejects, sel, opts)
    except BaseException:
        # an interrupted run keeps its parts only when it was asked to be resumable (--resume)
        if parts is not None:
            if not opts.resume:
                shutil.rmtree(parts, ignore_errors=True)
            unlock_parts(parts)
        raise
    if parts is not None:
        _drop_parts_after_commit(parts)
    summary["output"] = str(output)
    return summary


def _parts(output, opts, units, cfg, inputs):
    """The locked parts folder of this run, checked against an interrupted run's with ``--resume``."""

    fp = fingerprint(cfg, units, opts, inputs)
    with critical():  # a signal waits until the folder is known and registered for cleanup
        parts = prepare_parts(
            fp, output, opts.resume, opts.overwrite, compared=HOW_COMPARED, differ="other rows, boxes or images"
        )
        if not opts.resume and current() is not None:
            current().on_abort(lambda: shutil.rmtree(parts, ignore_errors=True))  # whatever ends the run
    return parts


def _drop_parts_after_commit(parts) -> None:
    """The parts go once the output is committed (they hold the only copy of finished units until then)."""

    def drop():
        shutil.rmtree(parts, ignore_errors=True)
        unlock_parts(parts)

    txn = current()
    if txn is None:
        drop()
    else:
        txn.after_commit(drop)
