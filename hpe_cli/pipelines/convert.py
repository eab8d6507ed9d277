"""``hpe convert`` as a streaming job: read batches, convert, write atomically."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import HpeError
from ..io import (
    LABEL_COLS,
    Rejects,
    TableWriter,
    batch_rotations,
    label_mode,
    open_table,
    rotation_value_columns,
    system_metadata,
)
from ..io.readers import LINE_COL
from ..rotation import soa
from ..rotation.convert import soa_labels


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
    import pyarrow as pa

    X, ok, reasons = batch_rotations(batch, source, mode, radians)
    if reasons is not None:
        X = [[v[ok] for v in row] for row in X]
    n = int(ok.sum())
    A = source.soa_to_canonical(X)
    labels = soa_labels(A, target, n)
    extra = rotation_value_columns(target, labels["matrix"], n)
    if decoder is not None:
        from ..rotation.decoders import decoder_columns

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


def run_convert(
    input_path,
    output,
    source,
    target,
    *,
    radians=False,
    rejects_path=None,
    overwrite=False,
    batch_size=65_536,
    progress=None,
    workers=None,
    strict=False,
    decoder=None,
    exclude=None,
) -> ConvertSummary:
    """Convert every row of ``input_path`` from ``source`` to ``target`` into ``output``.

    Bad rows go to ``rejects_path`` when given; otherwise (or with
    ``strict``) any bad row makes the job fail at the end with an error naming
    the file, how many rows, the first one and its reason, and nothing is
    written (see :func:`hpe_cli.io.rejects.rejects_rule`). Batches are converted on ``workers`` threads
    (numpy and Arrow release the GIL) while this thread reads and writes in
    order; at most ``workers + 1`` batches are in flight, so memory stays flat. ``exclude`` (a key list
    file, :mod:`hpe_cli.io.exclude`) drops the rows it names; they go to the rejects file as a choice.
    """
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    src = open_table(input_path, batch_size, with_lines=True)
    from ..io.system_meta import resolve_system

    resolved = resolve_system(src, source, default=None, option_name="--from")
    source = resolved.system
    mode = label_mode(src.columns, src.path, source)
    rejects = Rejects(rejects_path, overwrite, strict=strict, source=src)
    summary = ConvertSummary(source=source.name, source_origin=resolved.origin_text)
    if progress is not None and src.num_rows:  # Parquet metadata, .mat file counts: the bar has a total
        progress.total = src.num_rows
    meta = {**system_metadata(target), "hpe:source_system": source.name, "hpe:input": str(src.path)}
    if decoder is not None:
        meta["hpe:decoder"] = decoder
    from .pools import default_threads

    workers = default_threads(workers)  # --threads; one per core by default

    def finish(batch, read_rejects, future, writer):
        out, reasons, labels = future.result()
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
        if out.num_rows or writer.rows == 0:
            writer.write(out)
        summary.written += out.num_rows
        summary.gimbal_lock += int(labels["gimbal_lock"].sum())
        if labels["roundtrip_err"].size:
            summary.max_roundtrip_err = max(summary.max_roundtrip_err, float(labels["roundtrip_err"].max()))
        if progress is not None:
            progress.update(batch.num_rows)

    if exclude is not None:
        from ..io.exclude import ExcludeList

        exclude = ExcludeList(exclude)
        exclude.check_input(src.columns)  # before anything is written, even for an empty input
    with TableWriter(output, overwrite, meta) as writer, ThreadPoolExecutor(workers) as pool:
        pending = deque()
        try:
            for batch, read_rejects in src.batches_with_rejects():
                if exclude is not None:
                    batch = _exclude(batch, exclude, rejects, summary)
                pending.append(
                    (batch, read_rejects, pool.submit(convert_batch, batch, mode, source, target, radians, decoder))
                )
                if len(pending) > workers:
                    finish(*pending.popleft(), writer)
            while pending:
                finish(*pending.popleft(), writer)
        finally:
            for _, _, fut in pending:
                fut.cancel()
        if summary.rows == 0:
            raise HpeError(f"{src.path}: empty table (no rows)")
        rejects.finish()
    summary.rejects = dict(rejects.counts)
    return summary


def _exclude(batch, exclude, rejects, summary):
    """``batch`` without the rows ``exclude`` names; those go to the rejects file with their reason."""
    import pyarrow as pa

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
