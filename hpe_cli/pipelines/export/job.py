"""``hpe export`` as one job: load inputs -> select/split -> place pixels -> write layout."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import HpeError
from ...io.export import get_layout
from . import pixels, write
from .inputs import load_inputs
from .options import ExportOptions
from .select import select


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
    from ...rotation.systems import get_system

    try:
        layout = get_layout(opts.layout, system=opts.system, form=opts.form, trainer=opts.trainer)
    except ValueError as exc:
        raise HpeError(str(exc)) from None
    if layout.system is not None and opts.system is not None and get_system(opts.system).name != layout.system:
        raise HpeError(
            f"--layout {layout.name} stores labels in the {layout.system} system, which its trainer "
            f"expects; --system {get_system(opts.system).name} cannot be used with it"
        )
    return layout, get_system(layout.system or opts.system or "300w_lp")


def run_export(inputs, output, opts: ExportOptions, progress=None) -> dict:
    """Export ``inputs`` to the folder ``output`` (see the package docstring). Returns the summary dict."""
    from ...io import Rejects

    output = Path(output)
    _check_output(inputs, output, opts)
    rejects = Rejects(opts.rejects, opts.overwrite)
    layout, system = _layout_and_system(opts)
    # stage 1 and 2: the label table, the layout's rules, splits and sampling
    rows = load_inputs(inputs, opts.images, opts.input_system, landmarks=layout.uses_landmarks, radians=opts.radians)
    sel = select(rows, layout, system, opts)
    # stage 3: crop geometry and one task per source image
    plan = pixels.plan_crops(sel, layout, opts)
    todo = np.flatnonzero(sel.reasons == "")
    if todo.size == 0:
        raise write.nothing_left(layout, sel.reasons, np.arange(sel.n), "every label is rejected")
    pixels.name_files(sel, layout, plan, todo)
    tasks = pixels.build_tasks(sel, layout, plan, todo)
    splits_used = sorted(set(sel.split[todo].tolist()))
    try:
        layout.check_splits(splits_used)
    except ValueError as exc:
        raise HpeError(str(exc)) from None
    final_root = output.resolve()
    with write.staged_dir(output, opts.overwrite) as stage:
        layout.open(stage, splits_used)
        cfg = pixels.worker_config(stage, layout, splits_used, opts)
        bar = progress(total=int(todo.size)) if progress else None
        try:
            px = pixels.run_tasks(tasks, cfg, sel, layout, plan, opts.workers, bar)
            img_rej = px.status != ""
            sel.reasons[img_rej] = px.status[img_rej]
            # stage 4: the layout's index files, the summary, the rejects
            exported, notes_extra = write.write_index(stage, layout, sel, plan, px, todo, system, final_root)
        except BaseException:
            layout.abort()
            raise
        finally:
            if bar is not None:
                bar.close()
        summary = write.summary_of(layout, system, inputs, sel, plan, exported, notes_extra, opts)
        write.write_summary(stage, summary)
        write.write_rejects(rejects, sel, opts)
    summary["output"] = str(output)
    return summary
