"""``hpe augment`` as a streaming job: read batches, move labels/landmarks/boxes (and images), write."""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ...geometry.landmark_schemes import flip_permutation, scheme_for_count
from ...io import Rejects, TableWriter, check_output, system_metadata
from ...io.label_source import open_labels
from ...io.rejects import fail_all_rejected
from ...io.transaction import ensure_transaction, staged_dir
from ..pools import default_threads, run_in_order
from .batches import BatchPlan, batches_or_empty
from .images import ImageJob
from .options import AugmentOptions, for_input


def run_augment(input, output, opts: AugmentOptions, *, bar=None) -> dict:
    """Augment a label table (and optionally its images). Returns a summary dict.

    ``opts.image_size`` (``(W, H)`` or None) is checked against the table's ``image_width/image_height`` and the
    images; a row where two of them disagree is rejected. ``opts.op = "crop"`` with ``opts.crop = (x, y, w, h)``
    cuts the images to that rectangle. Batches are transformed on ``opts.threads`` threads (default: one per core,
    at most 8) while this thread reads, moves images and writes in order; at most ``threads + 1`` batches are in
    flight.
    A ``.mat`` folder without ``opts.images_dir`` uses its own images (:func:`~.options.for_input`): an image
    found there gives (and checks) the row's size, a missing one is no reject. ``bar``: a tqdm-like progress bar.
    """
    path = Path(input)
    opts = for_input(input, opts)
    check_output(output, opts.overwrite)
    # the file's own system, else --system; .mat Pose_Para is always 300w_lp, the output in --system
    labels = open_labels(path, opts.system, option_is_output=True, batch_size=opts.batch_size)
    plan = BatchPlan(labels, opts)
    rejects = Rejects(
        opts.rejects, opts.overwrite, strict=opts.strict, source=None if plan.mat_base is not None else labels.table
    )
    sink = _Sink(plan, rejects, bar)
    if bar is not None and labels.num_rows is not None:
        bar.total = labels.num_rows
        getattr(bar, "refresh", lambda: None)()
    with ensure_transaction(), contextlib.ExitStack() as stack:
        if opts.out_images is not None:
            sink.job = _image_job(stack.enter_context(staged_dir(opts.out_images, opts.overwrite)), path, plan, opts)
        sink.writer = stack.enter_context(TableWriter(output, opts.overwrite, _metadata(plan, opts)))
        run_in_order(batches_or_empty(labels.table), plan.work, sink.finish, default_threads(opts.threads))
        rejects.check()  # without --rejects (or with --strict) any bad row fails the run: nothing is written
        if sink.rows and not sink.written:  # the rejects file is still written: it says why
            fail_all_rejected(
                rejects,
                f"{path}: nothing augmented: all {sink.rows} row(s) rejected "
                f"({rejects.first_where or 'see the rejects file'})",
            )
        rejects.finish()
    return _summary(plan, opts, sink)


def _perm_of(n):
    """The left/right permutation of ``n`` landmarks (a built-in scheme's), or None."""
    name = scheme_for_count(n)
    return None if name is None else flip_permutation(name)


def _image_job(stage, path: Path, plan: BatchPlan, opts: AugmentOptions) -> ImageJob:
    """The pictures' writer into the staged ``--out-images`` folder (and the ``.mat`` files of a ``.mat`` folder,
    whose Pose_Para are in the reader's system: the labels' own)."""
    if not plan.mat_input:
        return ImageJob(stage, opts, perm_of=_perm_of)
    return ImageJob(stage, opts, mat_dir=path, mat_system=plan.in_system, perm_of=_perm_of)


def _metadata(plan: BatchPlan, opts: AugmentOptions) -> dict:
    """The output table's metadata: its system and the ``hpe:augment`` record of the operation."""
    return {
        **system_metadata(plan.system),
        "hpe:augment": {
            "op": opts.op,
            "angle_deg": opts.angle,
            "crop": list(opts.crop) if opts.crop else None,
            "scale": opts.scale,
            "description": opts.description,
            "image_size": list(opts.image_size) if opts.image_size else "from image_width/image_height or the images",
            "landmarks": plan.lm_text,
            "box_from": opts.box_from,
            "clip": opts.clip,
            "pixel_convention": "pixel centres at integer coordinates; centre ((W-1)/2, (H-1)/2)",
        },
    }


def _summary(plan: BatchPlan, opts: AugmentOptions, sink: _Sink) -> dict:
    """The run's summary dict (what the command prints)."""
    box_text = (
        f"{sink.boxes} moved ({opts.box_from}{', clipped' if opts.clip else ''})" if plan.has_box else "none in input"
    )
    return {
        "system": plan.system.name,
        "rows": sink.rows,
        "written": sink.written,
        "label_source": plan.label_source,
        "landmarks": plan.lm_text,
        "boxes": box_text,
        "images": len(sink.job.done) if sink.job else 0,
        "mats": sink.job.mats if sink.job else 0,
        "rejects": dict(sink.rejects.counts),
    }


class _Sink:
    """The main thread's side of the run: rejects, images and the table, batch by batch in input order."""

    def __init__(self, plan: BatchPlan, rejects: Rejects, bar):
        self.plan, self.rejects, self.bar = plan, rejects, bar
        self.job: ImageJob | None = None
        self.writer: TableWriter | None = None
        self.rows = self.written = self.boxes = 0

    def finish(self, _, read_rejects, result):
        """One batch done (``run_in_order``'s ``finish``): its rejects, its pictures, its rows."""
        batch, lines, reasons, keep, out, boxes, extra = result
        self.rejects.add_unreadable(read_rejects)
        self.rows += len(read_rejects)
        if not keep.all():
            self._reject(batch, lines, reasons, ~keep)
        if self.job is not None:
            # the image work is the slow part: move the bar per row as its picture is done
            self.job.add_rows(
                self._image_rows(lines, keep, extra), tick=self.bar.update if self.bar is not None else None
            )
        self.writer.write(out)
        self.boxes += boxes
        self.rows += batch.num_rows
        self.written += int(keep.sum())
        if self.bar is not None:
            self.bar.update(batch.num_rows - (int(keep.sum()) if self.job is not None else 0))

    def _reject(self, batch, lines, reasons, drop):
        """The dropped rows into the rejects, each named by its line/row (a ``.mat`` record by its file)."""
        plan, rejects = self.plan, self.rejects
        cols = {c: batch.column(i).to_numpy(zero_copy_only=False)[drop] for i, c in enumerate(batch.schema.names)}
        if plan.mat_base is not None:  # a .mat file is one record: named by its file, as the messages do
            cols["file"] = np.array([plan.where(0, f) for f in cols["file"]], dtype=object)
            if rejects.first_where is None:
                rejects.first_where = f"{cols['file'][0]}: {reasons[drop][0]}"
        else:
            cols = {"row": plan.numbers(lines[drop]), **cols}
        rejects.add(cols, reasons[drop], lines=lines[drop] if plan.csv else None)

    def _image_rows(self, lines, keep, extra) -> list:
        """:meth:`ImageJob.add_rows`'s rows for the kept rows of a batch."""
        plan, job = self.plan, self.job
        refs, names, P, wh_in, wh_out, A2, files = extra
        rows = []
        for i in np.flatnonzero(keep):
            mat = None
            if job.mat_dir is not None and files is not None:
                base = job.mat_dir if job.mat_dir.is_dir() else job.mat_dir.parent
                mat = (base / files[i], A2[i], plan.roi_fn, plan.zoom)
            where = plan.where(lines[i], files[i] if files else None)
            rows.append((names[i] or "", where, refs[i], P[i], wh_in[i], wh_out[i], plan.mirror, mat))
        return rows
