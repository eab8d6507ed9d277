"""``hpe evaluate``'s key join in memory: key choice, key codes (as written or on file stems), duplicates.

Pairing is by key columns only: when both files list the same keys in the same order the chunks are paired as
they stream (:mod:`.lockstep`); otherwise both sides are partitioned by a hash of the key on disk
(:mod:`.spill`) and each partition joined here with Arrow dictionary encoding or verified key hashes
(:func:`~hpe_cli.pipelines.evaluate.sides.read_side` + :func:`join` whole in memory is the reference it is
tested against). Row order is used only with ``--join order`` and equal row counts.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from ...errors import HpeError
from ...io.layout import arrow_to_numpy
from .sides import Side, file_stems

#: key columns tried in order when --key is not given
DEFAULT_KEYS = ("image", "file")


class JoinUsageError(HpeError):
    """A join that cannot be made as asked (the CLI turns it into a usage error, exit 2)."""

    exit_code = 2


def choose_keys(keys, pred_cols, gt_cols, pred_path, gt_path, join_mode="key"):
    if join_mode == "order":
        return []
    if keys:
        for side_cols, p in ((gt_cols, gt_path), (pred_cols, pred_path)):
            bad = [k for k in keys if k not in side_cols]
            if bad:
                raise HpeError(
                    f"{p}: --key column(s) {', '.join(bad)} not in the table; found: {', '.join(side_cols[:20])}"
                )
        return list(keys)
    for k in DEFAULT_KEYS:
        if k in pred_cols and k in gt_cols:
            return [k]
    raise JoinUsageError(
        f"{pred_path}: no key column shared with {gt_path} (looked for {', '.join(DEFAULT_KEYS)}; "
        f"prediction columns: {', '.join(pred_cols[:12])}); give --key COL[,COL...], or "
        "--join order to pair rows by position (only with equal row counts)"
    )


def _encode(a, b):

    enc = pa.concat_arrays([a, b]).dictionary_encode(null_encoding="encode")
    return arrow_to_numpy(enc.indices).astype(np.int64), len(enc.dictionary)


def _key_codes(gt_keys, pred_keys, keys, stems=None):
    """One int64 code per row of each side (equal codes iff all key columns are equal) and the notes.

    Text keys that name files are compared as written; when that matches fewer
    rows than comparing their file stems (``image00050.jpg``, ``AFLW/image00050.mat``
    and ``image00050`` are one image), the stems are used and a note says so. ``stems`` (a set of key
    columns), when given, makes that choice instead (the partitioned join decides it over the whole files).
    """
    import pyarrow.compute as pc  # lazy: start-up (0.06 s; the streamed run with equal keys needs none)

    n_g = gt_keys.num_rows
    code, notes = None, []
    for k in keys:
        a = gt_keys.column(k).combine_chunks()
        b = pred_keys.column(k).combine_chunks()
        if a.type != b.type:  # a key read as numbers on one side and text on the other: compare as text
            a, b = pc.cast(a, pa.string()), pc.cast(b, pa.string())
        c, m = _encode(a, b)
        if stems is not None:
            if k in stems:
                c, m = _encode(file_stems(a), file_stems(b))
                notes.append(f"key {k!r} joined on file stems (the two files spell the names differently)")
        elif pa.types.is_string(a.type) or pa.types.is_large_string(a.type):
            exact = np.isin(c[:n_g], c[n_g:]).sum()
            if exact < min(n_g, len(c) - n_g):
                cs, ms = _encode(file_stems(a), file_stems(b))
                if np.isin(cs[:n_g], cs[n_g:]).sum() > exact:
                    c, m = cs, ms
                    notes.append(f"key {k!r} joined on file stems (the two files spell the names differently)")
        if code is None:
            code = c
        else:
            code = code * m + c
            code = np.unique(code, return_inverse=True)[1].astype(np.int64).reshape(-1)
    return code[:n_g], code[n_g:], notes


def where(side, row):
    unit = side.unit
    if side.image_dir is not None:
        return f"{side.path}"
    return f"{side.path}: {unit} {int(side.lines[row])}"


def _check_unique(codes, side, keys):
    counts = np.bincount(codes) if len(codes) else np.zeros(0, dtype=np.int64)
    dup = counts[codes] > 1
    if dup.any():
        first = int(np.flatnonzero(dup)[0])
        again = int(np.flatnonzero(codes == codes[first])[1])
        what = ", ".join(f"{k}={side.keys.column(k)[first].as_py()!r}" for k in keys)
        unit = side.unit
        raise HpeError(
            f"{where(side, first)}: duplicate key {what} (again at {unit} {int(side.lines[again])}); "
            f"choose --key columns that identify one row, e.g. --key {','.join(keys)},person_id"
        )


class Matched:
    """The verified pairs of a partition (:meth:`hpe_cli.pipelines.evaluate.spill.Partitions.codes`): each side's
    rows are unique; ``gt_rows`` ascending, ``pred_rows[i]`` the prediction row of ``gt_rows[i]``."""

    __slots__ = ("gt_rows", "pred_rows")

    def __init__(self, gt_rows, pred_rows):
        self.gt_rows, self.pred_rows = gt_rows, pred_rows


def join(pred: Side, gt: Side, keys, join_mode="key", stems=None, codes=None):
    """``(gt_idx, pred_idx, unmatched prediction rows, notes)``; pred_idx is -1 where a GT row has no prediction.

    ``stems``: see :func:`_key_codes`; ``codes``: the ``(gt, pred)`` key codes when the caller has them, or the
    pairs themselves (a :class:`Matched`; the partitioned join, from verified key hashes)."""
    if join_mode == "order":
        if pred.n != gt.n:
            raise JoinUsageError(
                f"{pred.path}: --join order pairs rows by position and needs equal row counts; "
                f"got {pred.n} predictions and {gt.n} ground-truth rows in {gt.path}"
            )
        idx = np.arange(gt.n)
        return idx, idx.copy(), np.zeros(0, dtype=np.int64), ["rows paired by position (--join order)"]
    if codes is not None:
        notes = [
            f"key {k!r} joined on file stems (the two files spell the names differently)"
            for k in keys
            if k in (stems or ())
        ]
        if isinstance(codes, Matched):  # the pairs themselves: no codes to build
            pidx = np.full(gt.n, -1, dtype=np.int64)
            pidx[codes.gt_rows] = codes.pred_rows
            paired = np.zeros(pred.n, dtype=bool)
            paired[codes.pred_rows] = True
            return np.arange(gt.n), pidx, np.flatnonzero(~paired), notes
        cg, cp = codes
    else:
        cg, cp, notes = _key_codes(gt.keys, pred.keys, keys, stems)
        _check_unique(cg, gt, keys)  # codes from the key hashes are unique on each side (see Partitions.codes)
        _check_unique(cp, pred, keys)
    m = int(max(cg.max(initial=-1), cp.max(initial=-1))) + 1
    pred_pos = np.full(m, -1, dtype=np.int64)
    pred_pos[cp] = np.arange(len(cp))
    gt_has = np.zeros(m, dtype=bool)
    gt_has[cg] = True
    return np.arange(len(cg)), pred_pos[cg], np.flatnonzero(~gt_has[cp]), notes


def row_reasons(side: Side, idx):
    if side.reasons is None:
        return np.full(len(idx), "", dtype=object)
    return side.reasons[idx]


def _gather(side, idx):
    """Canonical nested matrix of the rows ``idx`` (no copy when every row is used in its own order)."""
    if len(idx) == side.n and (idx[0] == 0 if len(idx) else True) and np.all(np.diff(idx) == 1):
        return [[side.canonical[3 * i + j] for j in range(3)] for i in range(3)]
    return [[side.canonical[3 * i + j][idx] for j in range(3)] for i in range(3)]
