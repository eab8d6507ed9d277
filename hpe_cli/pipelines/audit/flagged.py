"""``hpe audit -o``: a second pass over the input writing every column, one boolean column per check, 'flagged'."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from ...io import TableWriter, open_table, system_metadata
from ...rotation.audit import CHECKS
from .batches import SKIP_REJECTS, check_batch, read_batches, system_cols


def write_flagged(plan, options, dups, cons) -> None:
    """Write ``options.output``: the input's columns, then the checks' columns (and ``cons``'s, if any).

    Each batch's flags are recomputed (memory stays flat); ``duplicates`` come
    from ``dups`` (:class:`~hpe_cli.pipelines.audit.duplicates.Duplicates`,
    finished). With ``options.only_flagged`` only the flagged rows are written.
    """
    names = list(CHECKS) + ["flagged"]
    extra = list(cons.output_columns) if cons is not None else []  # --consistency columns
    src = open_table(plan.input_path, options.batch_size, with_lines=True)
    keep = [c for c in src.columns if c not in names + extra]
    meta = {**system_metadata(plan.system), "hpe:audit_of": str(src.path)}
    offset = 0
    with TableWriter(options.output, options.overwrite, meta) as w:
        for batch, _, _ in read_batches(src, plan.mode, SKIP_REJECTS):
            n = batch.num_rows
            cols, eff = system_cols(batch, plan.system, plan.mode, options.radians, plan.via_system)
            res = check_batch(cols, eff, plan.system, options.near_tol_deg)
            res["duplicates"] = dups.mask(offset, offset + n)
            any_flag = np.zeros(n, dtype=bool)
            for c in CHECKS:
                any_flag |= res[c]
            arrays = list(batch.select(keep).columns) + [pa.array(res[c]) for c in CHECKS] + [pa.array(any_flag)]
            if cons is not None:
                arrays += [pa.array(v) for v in cons.columns(offset, n).values()]
            out = pa.RecordBatch.from_arrays(arrays, names=keep + names + extra)
            if options.only_flagged:
                out = out.filter(pa.array(any_flag))
            if out.num_rows or w.rows == 0:
                w.write(out)
            offset += n
        if offset == 0:
            more = [pa.field(c, t) for c, t in cons.output_types().items()] if cons is not None else []
            empty = pa.schema([src.schema.field(c) for c in keep] + [pa.field(c, pa.bool_()) for c in names] + more)
            w.write(empty.empty_table())
