"""``hpe convert`` as a streaming job: read batches, convert, write atomically."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa

from ..errors import HpeError
from ..io import LABEL_COLS, Rejects, TableWriter, batch_rotations, rotation_value_columns, system_metadata
from ..io.exclude import ExcludeList
from ..io.label_source import LabelSource, open_labels
from ..io.readers import LINE_COL
from ..io.table_source import DEFAULT_BATCH
from ..rotation import soa
from ..rotation.convert import soa_labels
from ..rotation.decoders import DECODERS, decoder_columns
from .heap import keep_freed_memory
from .pools import default_threads, run_in_order


@dataclass
class ConvertSummary:
    rows: int = 0
    written: int = 0
    gimbal_lock: int = 0
    max_roundtrip_err: float = 0.0
    rejects: dict = field(default_factory=dict)
    #: the input's system and where it came from ("file metadata", "option", "default")
    source: str = ""
    source_origin: str = ""
    #: rows dropped by ``exclude``
    excluded: int = 0


def convert_batch(batch, mode, source, target, radians=False, decoder=None):
    """Convert one record batch.

    Returns ``(out_batch, reasons, labels)``: the converted rows (input columns
    that the conversion does not replace, then ``LABEL_COLS``, then the
    target's own value columns when it has any -- e.g. ``rx, ry, rz`` for
    ``img2pose`` -- then the ``decoder_*`` columns when ``decoder`` is given),
    the per-row reject reason ('' for converted rows; None when every row
    converted) and the label dict of :func:`~hpe_cli.rotation.convert.soa_labels`.
    """
    X, ok, reasons = batch_rotations(batch, source, mode, radians)
    if reasons is not None:
        X = [[v[ok] for v in row] for row in X]
    n = int(ok.sum())
    A = source.soa_to_canonical(X)
    labels = soa_labels(A, target, n)
    extra = rotation_value_columns(target, labels["matrix"], n)
    if decoder is not None:
        extra.update(decoder_columns(decoder, soa.to_array(A, n)))
    replaced = set(LABEL_COLS) | set(extra) | {LINE_COL}
    keep = [name for name in batch.schema.names if name not in replaced]
    kept = batch.select(keep)
    if not ok.all():
        kept = kept.filter(pa.array(ok))
    new = (
        labels["primary"]
        + labels["secondary"]
        + soa.columns(labels["matrix"], n)
        + [labels["gimbal_lock"], labels["roundtrip_err"]]
        + list(extra.values())
    )
    names = keep + LABEL_COLS + [c for c in extra if c not in LABEL_COLS]
    new = new[: len(LABEL_COLS)] + [v for c, v in extra.items() if c not in LABEL_COLS]
    arrays = list(kept.columns) + [pa.array(np.asarray(v)) for v in new]
    return pa.RecordBatch.from_arrays(arrays, names=names), reasons, labels


@dataclass(frozen=True)
class ConvertOptions:
    """The settings of one ``hpe convert`` run, validated once (built by ``cli/convert.py`` and the API alike).

    Attributes
    ----------
    radians : bool
        Angle labels are in radians (``--radians``).
    rejects : str or path, optional
        File for the rows that cannot be converted, with their reason (``--rejects``); without it (or with
        ``strict``) any such row makes the run fail and nothing is written.
    strict : bool
        ``--strict``: a rejected row is an error even with ``rejects``.
    overwrite : bool
        Replace an existing output.
    batch_size : int
        Rows per record batch, >= 1.
    threads : int, optional
        Threads converting batches, >= 1 (``--threads``); None: one per core
        (:func:`hpe_cli.pipelines.pools.default_threads`). The output does not depend on it.
    decoder : str, optional
        Also write what this published decoder prints (``decoder_*`` columns).
    exclude : str or path, optional
        A key list file (:mod:`hpe_cli.io.exclude`) whose rows are dropped (to the rejects file, as a choice).
    """

    radians: bool = False
    rejects: object = None
    strict: bool = False
    overwrite: bool = False
    batch_size: int = DEFAULT_BATCH
    threads: int | None = None
    decoder: str | None = None
    exclude: object = None

    def __post_init__(self):
        checks = [
            (isinstance(self.batch_size, int) and self.batch_size >= 1, "batch_size >= 1", self.batch_size),
            (self.threads is None or int(self.threads) >= 1, "threads >= 1", self.threads),
            (self.decoder is None or self.decoder in DECODERS, f"decoder among {', '.join(DECODERS)}", self.decoder),
        ]
        for ok, expected, got in checks:
            if not ok:
                raise HpeError(f"convert options: expected {expected}, got {got!r}")


class ConvertedBatches:
    """Takes each converted batch in input order: writes it, sends its bad rows to the rejects, sums up."""

    def __init__(self, writer, rejects, summary: ConvertSummary, progress=None):
        self.writer, self.rejects, self.summary, self.progress = writer, rejects, summary, progress

    def finish(self, batch, read_rejects, result) -> None:
        out, reasons, labels = result
        rejects, summary = self.rejects, self.summary
        bad = np.flatnonzero(reasons != "") if reasons is not None else ()
        lines = batch.column(LINE_COL).to_numpy()
        rejects.add_unreadable(read_rejects)
        summary.rows += len(read_rejects)
        if len(bad):
            cols = {"row": lines[bad]}
            if rejects.path is not None:
                cols.update(
                    {
                        n: batch.column(n).take(bad).to_numpy(zero_copy_only=False)
                        for n in batch.schema.names
                        if n != LINE_COL
                    }
                )
            rejects.add(cols, reasons[bad], lines=lines[bad])
        summary.rows += batch.num_rows
        if out.num_rows or self.writer.rows == 0:
            self.writer.write(out)
        summary.written += out.num_rows
        summary.gimbal_lock += int(labels["gimbal_lock"].sum())
        if labels["roundtrip_err"].size:
            summary.max_roundtrip_err = max(summary.max_roundtrip_err, float(labels["roundtrip_err"].max()))
        if self.progress is not None:
            self.progress.update(batch.num_rows)


def output_metadata(labels: LabelSource, target, decoder=None) -> dict:
    """The output's Parquet metadata: the target system's definition, the source system and the input."""
    meta = {**system_metadata(target), "hpe:source_system": labels.system.name, "hpe:input": str(labels.path)}
    if decoder is not None:
        meta["hpe:decoder"] = decoder
    return meta


def run_convert(input_path, output, source, target, options: ConvertOptions | None = None, *, progress=None):
    """Convert every row of ``input_path`` from ``source`` to ``target`` into ``output``.

    Parameters
    ----------
    input_path : str or path
        Any label table ``hpe`` reads.
    output : str or path
        ``.parquet`` or ``.csv``, written atomically.
    source : RotationSystem or None
        ``--from``: the input's system when the file names none (None: the file must name it).
    target : RotationSystem
        ``--to``.
    options : ConvertOptions, optional
    progress : tqdm-like, optional

    Returns
    -------
    ConvertSummary

    Notes
    -----
    Bad rows go to ``options.rejects`` when given; otherwise (or with
    ``strict``) any bad row makes the job fail at the end with an error naming
    the file, how many rows, the first one and its reason, and nothing is
    written (see :func:`hpe_cli.io.rejects.rejects_rule`). Batches are converted on ``options.threads``
    threads (numpy and Arrow release the GIL) while this thread reads and writes in
    order; at most ``threads + 1`` batches are in flight, so memory stays flat. ``options.exclude`` (a key
    list file, :mod:`hpe_cli.io.exclude`) drops the rows it names; they go to the rejects file as a choice.
    """
    o = options if options is not None else ConvertOptions()
    labels = open_labels(input_path, source, default=None, option_name="--from", batch_size=o.batch_size)
    src, source, mode = labels.table, labels.system, labels.mode
    rejects = Rejects(o.rejects, o.overwrite, strict=o.strict, source=src)
    summary = ConvertSummary(source=source.name, source_origin=labels.origin)
    if progress is not None and src.num_rows:  # Parquet metadata, .mat file counts: the bar has a total
        progress.total = src.num_rows
    exclude = None
    if o.exclude is not None:
        exclude = ExcludeList(o.exclude)
        exclude.check_input(src.columns)  # before anything is written, even for an empty input

    def items():
        for batch, read_rejects in src.batches_with_rejects():
            if exclude is not None:
                batch = _exclude(batch, exclude, rejects, summary)
            yield batch, read_rejects

    def work(batch):
        return convert_batch(batch, mode, source, target, o.radians, o.decoder)

    with TableWriter(output, o.overwrite, output_metadata(labels, target, o.decoder)) as writer:
        keep_freed_memory()  # the batches' freed temporaries reused, not faulted in again (pipelines.heap)
        done = ConvertedBatches(writer, rejects, summary, progress)
        run_in_order(items(), work, done.finish, default_threads(o.threads))  # --threads; one per core by default
        if summary.rows == 0:
            raise HpeError(f"{src.path}: empty table (no rows)")
        rejects.finish()
    summary.rejects = dict(rejects.counts)
    return summary


def _exclude(batch, exclude, rejects, summary):
    """``batch`` without the rows ``exclude`` names; those go to the rejects file with their reason."""

    why = exclude.reasons(batch)
    hit = why != ""
    if not hit.any():
        return batch
    lines = batch.column(LINE_COL).to_numpy()
    mask = pa.array(hit)
    cols = {"row": lines[hit]}
    cols.update(
        {n: batch.column(n).filter(mask).to_numpy(zero_copy_only=False) for n in batch.schema.names if n != LINE_COL}
    )
    rejects.add_choice(cols, why[hit])
    summary.rows += int(hit.sum())
    summary.excluded += int(hit.sum())
    return batch.filter(pa.array(~hit))
