"""``hpe convert`` as a streaming job: read batches, convert, write atomically."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import HpeError
from ..io import (LABEL_COLS, Rejects, TableWriter, batch_labels, conversion_columns, label_mode, open_table,
                  system_metadata)
from ..rotation import convert_angles, convert_matrices


@dataclass
class ConvertSummary:
    rows: int = 0
    written: int = 0
    gimbal_lock: int = 0
    max_roundtrip_err: float = 0.0
    rejects: dict = field(default_factory=dict)


def convert_batch(batch, mode, source, target, radians=False):
    """Convert one record batch.

    Returns ``(out_batch, reasons)``: the converted rows (input columns that
    the conversion does not replace, then ``LABEL_COLS``) and the per-row
    reject reason ('' for converted rows).
    """
    import pyarrow as pa

    values, reasons = batch_labels(batch, mode, radians)
    ok = reasons == ""
    conv = (convert_angles if mode == "angles" else convert_matrices)(values[ok], source, target)
    keep = [n for n in batch.schema.names if n not in LABEL_COLS]
    kept = batch.select(keep)
    if not ok.all():
        kept = kept.filter(pa.array(ok))
    arrays = list(kept.columns) + [pa.array(v) for v in conversion_columns(conv).values()]
    out = pa.RecordBatch.from_arrays(arrays, names=keep + LABEL_COLS)
    return out, reasons, conv


def run_convert(input_path, output, source, target, *, radians=False, rejects_path=None, overwrite=False,
                batch_size=262_144, progress=None) -> ConvertSummary:
    """Convert every row of ``input_path`` from ``source`` to ``target`` into ``output``.

    Bad rows go to ``rejects_path`` when given; otherwise the first one aborts
    the job with an error naming the file, the row and the reason, and no
    output is left behind.
    """
    src = open_table(input_path, batch_size)
    mode = label_mode(src.columns, src.path)
    rejects = Rejects(rejects_path, overwrite)
    summary = ConvertSummary()
    meta = {**system_metadata(target), "hpe:source_system": source.name, "hpe:input": str(src.path)}
    with TableWriter(output, overwrite, meta) as writer:
        for batch in src.batches():
            out, reasons, conv = convert_batch(batch, mode, source, target, radians)
            bad = np.flatnonzero(reasons != "")
            if bad.size:
                if rejects.path is None:
                    raise HpeError(f"{src.path}: row {summary.rows + bad[0]}: {reasons[bad[0]]} "
                                   f"({bad.size} bad rows in this batch; use --rejects FILE to set them aside)")
                cols = {"row": summary.rows + bad}
                cols.update({n: batch.column(n).take(bad).to_numpy(zero_copy_only=False) for n in batch.schema.names})
                rejects.add(cols, reasons[bad])
            summary.rows += batch.num_rows
            if out.num_rows or writer.rows == 0:
                writer.write(out)
            summary.written += out.num_rows
            summary.gimbal_lock += int(conv.gimbal_lock.sum())
            if conv.roundtrip_err.size:
                summary.max_roundtrip_err = max(summary.max_roundtrip_err, float(conv.roundtrip_err.max()))
            if progress is not None:
                progress.update(batch.num_rows)
        if summary.rows == 0:
            raise HpeError(f"{src.path}: empty table (no rows)")
        rejects.write()
    summary.rejects = dict(rejects.counts)
    return summary
