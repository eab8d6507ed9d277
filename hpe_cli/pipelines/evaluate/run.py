"""``hpe evaluate``: pair predictions with ground truth by key, score every pair, write the outputs.

Memory is flat in the number of pairs whenever the two files list the same
keys in the same order (or ``--join order``): chunks are paired as they are
read (:func:`hpe_cli.pipelines.evaluate.lockstep.lockstep`, keys verified chunk by
chunk), every metric is summed per group (:class:`hpe_cli.metrics.stream.Accumulator`),
the geodesic errors are spilled as float32 for exact medians and percentiles,
and the per-row output is written chunk by chunk. Files in different orders
are hashed by key into partition files and joined one partition at a time
(:mod:`hpe_cli.pipelines.evaluate.spill`), then scored the same way.
Global estimates (``--align mean``, opal23's alignment) take one extra pass.
"""

from __future__ import annotations

import numpy as np

from ...errors import HpeError
from .dataset import choose_directmhp
from .join import LABEL_THREADS, Chunk, SideReader, choose_keys, join, read_side
from .lockstep import Unaligned, lockstep, prefetch
from .outputs import Images, empty_rows, worst_pictures
from .rejects import align_block, collect_rejects, unreadable_rejects
from .score import PLACEMENT, nested, raw_angles, score_pairs, take_rows, with_canonical

ANGLES = ("pitch", "yaw", "roll")


def _memory_pairs(gt, pred, gv, pv, batch_size):
    """Chunks of the joined valid pairs (in GT order) from two sides held in memory."""
    for a in range(0, len(gv), batch_size):
        gi, pi = gv[a : a + batch_size], pv[a : a + batch_size]
        if len(gi) and int(gi[-1]) - int(gi[0]) + 1 == len(gi):  # GT rows in order, none left out: a view
            gi = slice(int(gi[0]), int(gi[-1]) + 1)
        g = Chunk(
            None if gt.canonical is None else [x[gi] for x in gt.canonical],
            gt.ok[gi],
            None,
            None if gt.raw is None else gt.raw[gi],
            None,
            None
            if gt.keys is None
            else (gt.keys.slice(gi.start, gi.stop - gi.start) if isinstance(gi, slice) else gt.keys.take(gi)),
            None if gt.by is None else gt.by[gi],
            gt.lines[gi],
        )
        p = Chunk(
            None if pred.canonical is None else [x[pi] for x in pred.canonical],
            pred.ok[pi],
            None,
            None if pred.raw is None else pred.raw[pi],
            None if pred.dist is None else pred.dist[pi],
            None,
            None if pred.by is None else pred.by[pi],
            pred.lines[pi],
        )
        yield g, p


class _Settings:
    """Everything one run needs, so a pass can be repeated (re-read in streaming, replayed in memory)."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def _globals(s, pairs_factory, gsys, psys) -> dict:
    """Estimates over all pairs that the per-chunk scores need: --align mean's offset, opal23's mean."""
    import os
    import tempfile

    from ...metrics import peer_angles as pa_
    from ...metrics.align import project_to_so3
    from ...metrics.protocols import PosePair, opal23_mats

    need_mean = s.align == "mean"
    need_opal = "opal23-align" in s.protocols
    if not (need_mean or need_opal):
        return {}
    M, n = np.zeros((3, 3)), 0
    first, written = (np.iinfo(np.int64).max, 0), 0

    def work(gp):  # on a pool thread: pure numpy, no shared state
        g, p = with_canonical(gp[0], gsys), with_canonical(gp[1], psys)
        ok = g.ok & p.ok
        if not ok.all():
            g, p = take_rows(g, ok), take_rows(p, ok)
        P, G = nested(p), nested(g)
        part = None
        if need_mean:
            part = np.array(
                [[float(np.sum(P[k][0] * G[m][0] + P[k][1] * G[m][1] + P[k][2] * G[m][2])) for m in range(3)]
                 for k in range(3)]
            )  # fmt: skip
        deltas = near = None
        if need_opal and g.n:
            pair = PosePair(P, G, gsys, raw_angles(g, p, gsys, psys))
            Po, Go, _ = opal23_mats(pair)
            deltas, near = pa_.opal23_near_quats(Go, Po)
        return g.n, part, deltas, near, g.lines

    from concurrent.futures import ThreadPoolExecutor

    from ..pools import in_order

    fd, path = tempfile.mkstemp(prefix="hpe_eval_opal23_", suffix=".bin")
    threads = max(1, int(getattr(s, "threads", None) or 1))
    pool = ThreadPoolExecutor(threads, thread_name_prefix="hpe-evaluate-glob")
    pairs = pairs_factory()
    try:
        with os.fdopen(fd, "wb") as f:
            # chunks in input order whatever the threads: the same sums, the same spill
            for rows, part, deltas, near, lines in in_order(pool, work, pairs, ahead=threads):
                if part is not None:
                    for k in range(3):
                        for m in range(3):
                            M[k, m] += part[k, m]
                    n += rows
                if deltas is not None:
                    if near.any():  # the peer starts at its file's first row: the smallest GT line
                        ln = lines[near]
                        j = int(np.argmin(ln))
                        if ln[j] < first[0]:
                            first = (int(ln[j]), written + j)
                    written += len(deltas)
                    np.ascontiguousarray(deltas).tofile(f)
        out = {}
        if need_mean:
            out["Q"] = project_to_so3(M / n) if n else np.eye(3)
        if need_opal:
            size = os.path.getsize(path)
            with open(path, "rb") as f:  # read piece by piece: a memory map's pages would count in the peak
                out["opal23_mean"] = pa_.opal23_karcher(_Rows(f, size // 32, 4), start=first[1])
        return out
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if hasattr(pairs, "close"):  # an error or a signal: the readers' threads and temp files go now
            pairs.close()
        os.unlink(path)


class _Rows:
    """Rows of ``width`` float64 in an open binary file, read on indexing (``rows[a:b]``, ``rows[i]``): a spill
    as an array-like whose pages do not stay mapped (a ``np.memmap`` would add them to the process's peak)."""

    def __init__(self, f, n: int, width: int):
        self.f, self.n, self.width = f, int(n), int(width)
        self.ndim = 2

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k):
        if isinstance(k, slice):
            a, b, _ = k.indices(self.n)
            b = max(a, b)
        else:
            a, b = int(k), int(k) + 1
        self.f.seek(a * self.width * 8)
        out = np.fromfile(self.f, dtype=np.float64, count=(b - a) * self.width).reshape(-1, self.width)
        return out if isinstance(k, slice) else out[0]


def default_threads(threads=None) -> int:
    from ..pools import default_threads as d

    return d(threads)


def _readers(s, progress=None):
    gr = SideReader(
        s.gt_path,
        s.gt_system,
        s.use_gt,
        s.keys,
        s.by,
        s.radians,
        s.batch_size,
        progress,
        extra=PLACEMENT if s.html else (),
        role="gt",
        threads=min(s.threads, LABEL_THREADS),
    )
    pr = SideReader(
        s.pred_path,
        s.pred_system,
        s.use_pred,
        s.keys,
        s.by if s.by not in gr.columns else None,
        s.radians,
        s.batch_size,
        progress,
        s.orthonormalize,
        role="pred",
        threads=min(s.threads, LABEL_THREADS),
    )
    return gr, pr


def _run_stream(s, rej, writer):
    """Pair the chunks as they are read (same keys in the same order, or --join order)."""
    notes: set = set()

    def factory():
        gr, pr = _readers(s)
        return lockstep(gr, pr, s.keys, s.join_mode, set())

    gr, pr = _readers(s, s.progress)
    s.gside, s.pside = gr, pr
    glob = _globals(s, factory, gr.system, pr.system)
    out = score_pairs(
        s, prefetch(lockstep(gr, pr, s.keys, s.join_mode, notes)), rej, gr.system, pr.system, glob, writer, True
    )
    if s.join_mode == "order" and (gr.unreadable or pr.unreadable):
        side = gr if gr.unreadable else pr
        raise HpeError(
            f"{side.path}: line {side.unreadable[0][0]}: unreadable row ({side.unreadable[0][1]}): "
            "rows cannot be paired by position (--join order) once one is skipped"
        )
    for side, name in ((gr, "gt"), (pr, "pred")):
        unreadable_rejects(rej, side, name)
    n = {"gt": gr.n, "pred": pr.n, "missing": 0, "unmatched_pred": 0}
    return out, glob, n, sorted(notes), gr, pr


def _run_memory(s, rej, writer):
    """Read both sides whole, join them by key, then score the pairs in chunks."""
    gt = read_side(
        s.gt_path,
        s.gt_system,
        s.use_gt,
        s.keys,
        s.by,
        s.radians,
        s.batch_size,
        s.progress,
        role="gt",
        threads=min(s.threads, LABEL_THREADS),
    )
    pred = read_side(
        s.pred_path,
        s.pred_system,
        s.use_pred,
        s.keys,
        s.by if s.by not in gt.columns else None,
        s.radians,
        s.batch_size,
        s.progress,
        role="pred",
        orthonormalize=s.orthonormalize,
        threads=min(s.threads, LABEL_THREADS),
    )
    if pred.n == 0 and not pred.unreadable:
        raise HpeError(f"{pred.path}: no prediction rows (the file has a header only)")
    gidx, pidx, unmatched, notes = join(pred, gt, s.keys, s.join_mode)

    def key_cols(side, rows):
        if s.keys:
            return {k: side.keys.column(k).take(rows).to_numpy(zero_copy_only=False) for k in s.keys}
        return {"row": rows + 1}

    valid, missing, invalid = collect_rejects(rej, gt, pred, gidx, pidx, unmatched, key_cols)
    gv, pv = gidx[valid], pidx[valid]
    glob = _globals(s, lambda: _memory_pairs(gt, pred, gv, pv, s.batch_size), gt.system, pred.system)
    out = score_pairs(
        s, _memory_pairs(gt, pred, gv, pv, s.batch_size), rej, gt.system, pred.system, glob, writer, False
    )
    out[2]["invalid"] = int(invalid.sum())
    n = {"gt": gt.n, "pred": pred.n, "missing": int(missing.sum()), "unmatched_pred": len(unmatched)}
    return out, glob, n, notes, gt, pred


def _valid(gt, pred, gidx, pidx):
    p_ok = np.where(pidx < 0, False, pred.ok[np.maximum(pidx, 0)])
    return (pidx >= 0) & gt.ok[gidx] & p_ok


def _run_spill(s, rej, writer):
    """Key join of files in different orders: both sides hashed into partition files, joined one at a time
    (:mod:`hpe_cli.pipelines.evaluate.spill`); memory flat in the number of pairs."""
    from .spill import Partitions

    gr, pr = _readers(s, s.progress)
    s.gside, s.pside = gr, pr
    parts = Partitions(gr, pr, s.keys, getattr(s, "partition_rows", None)).fill()
    try:
        if pr.n == 0 and not pr.unreadable:
            raise HpeError(f"{pr.path}: no prediction rows (the file has a header only)")
        for side, name in ((gr, "gt"), (pr, "pred")):
            unreadable_rejects(rej, side, name)
        stems = parts.stem_columns()
        tally = {"missing": 0, "unmatched_pred": 0, "invalid": 0}
        notes: set = set()

        def key_cols(side, rows):
            if not len(rows):  # no row set aside (the usual case): no Arrow take, which would import pandas
                return {k: np.zeros(0, dtype=object) for k in s.keys}
            return {k: side.keys.column(k).take(rows).to_numpy(zero_copy_only=False) for k in s.keys}

        def pairs(first: bool):
            for k in range(parts.K):
                gt, pred = parts.sides(k)
                gidx, pidx, unmatched, nt = join(pred, gt, s.keys, "key", stems, parts.codes(gt, pred, stems))
                notes.update(nt)
                if first:
                    valid, missing, invalid = collect_rejects(rej, gt, pred, gidx, pidx, unmatched, key_cols)
                    tally["missing"] += int(missing.sum())
                    tally["invalid"] += int(invalid.sum())
                    tally["unmatched_pred"] += len(unmatched)
                else:
                    valid = _valid(gt, pred, gidx, pidx)
                yield from _memory_pairs(gt, pred, gidx[valid], pidx[valid], s.batch_size)
                del gt, pred, gidx, pidx

        glob = _globals(s, lambda: pairs(False), gr.system, pr.system)
        out = score_pairs(s, pairs(True), rej, gr.system, pr.system, glob, writer, False)
    finally:
        parts.cleanup()
    out[2]["invalid"] = tally["invalid"]
    n = {"gt": gr.n, "pred": pr.n, "missing": tally["missing"], "unmatched_pred": tally["unmatched_pred"]}
    s.partitions = parts.K
    return out, glob, n, sorted(notes), gr, pr


def _run(s, writer, stream: bool):
    from ...io import Rejects

    rej = Rejects(s.rejects, s.overwrite, strict=s.strict, source=None)
    run = _run_stream if stream else (_run_memory if getattr(s, "join_engine", "spill") == "memory" else _run_spill)
    out, glob, n, notes, gside, pside = run(s, rej, writer)
    rej.check()  # without --rejects (or with --strict) any set-aside row is an error: nothing is written
    if pside.n == 0 and not pside.unreadable:
        raise HpeError(f"{pside.path}: no prediction rows (the file has a header only)")
    if gside.n == 0 and not gside.unreadable:
        raise HpeError(f"{gside.path}: no ground-truth rows")
    return out, glob, n, notes, gside, pside, rej


def _result(s, rep, rep_before, counts, n, notes, gside, pside, glob, rej, streamed) -> dict:
    """The report dict of one run."""
    from ...metrics.protocols import PROTOCOLS

    result = {
        "n": {
            "gt": n["gt"],
            "pred": n["pred"],
            "pairs": counts["pairs"],
            "missing": n["missing"],
            "invalid": counts["invalid"],
            "unmatched_pred": n["unmatched_pred"],
        },
        "systems": {"pred": pside.system.name, "gt": gside.system.name},
        "system_origin": {"pred": pside.resolved.describe(), "gt": gside.resolved.describe()},
    }
    if gside.unreadable or pside.unreadable:
        result["n"]["unreadable"] = len(gside.unreadable) + len(pside.unreadable)
    if s.orthonormalize:
        result["n"]["orthonormalized"] = counts.get("orthonormalized", 0)
        result["orthonormalize"] = {
            "method": "nearest rotation (SVD, det +1) of each prediction matrix",
            "max_distance": counts.get("dist_max"),
            "mean_distance": counts["dist_sum"] / counts["pairs"]
            if counts.get("pairs") and "dist_sum" in counts
            else None,
        }
    result["align"] = align_block(glob, rep_before, gside.system) if s.align == "mean" else {"method": "none"}
    result["metrics"], result["protocols"] = rep["metrics"], rep["protocols"]
    if s.by:
        result["by"] = {"column": s.by, "groups": rep["by_groups"]}
    if s.yaw_bins:
        result["yaw_bins"] = rep["yaw_bins"]
    result["inputs"] = {
        "pred": str(pside.path),
        "gt": str(gside.path),
        "key": s.keys or "row order",
        "join": s.join_mode,
        "paired": "streamed in file order"
        if streamed
        else "joined in memory"
        if getattr(s, "join_engine", "spill") == "memory"
        else f"joined by key in {s.partitions} partition(s) on disk (external hash join)",
        "columns": {"pred": pside.mode, "gt": gside.mode},
    }
    result["notes"] = list(notes) + [f"{name}: {note}" for name in s.protocols for note in PROTOCOLS[name].notes]
    if rej.counts:
        result["rejects"] = dict(rej.counts)
    return result


def run_evaluate(
    pred_path,
    gt_path,
    *,
    pred_system,
    gt_system,
    output=None,
    keys=(),
    protocols=None,
    align="none",
    by=None,
    yaw_bins=None,
    report=None,
    plots=None,
    rejects=None,
    use_pred="auto",
    use_gt="auto",
    radians=False,
    overwrite=False,
    batch_size=262_144,
    progress=None,
    strict=False,
    join_mode="key",
    orthonormalize=False,
    html=None,
    worst=12,
    images=None,
    join_engine="spill",
    partition_rows=None,
    threads=None,
) -> dict:
    """Evaluate ``pred_path`` against ``gt_path``; write the requested outputs; return the report.

    Files in different orders are joined by an external hash join (``join_engine="spill"``, partitions of
    about ``partition_rows`` rows, :mod:`hpe_cli.pipelines.evaluate.spill`) or, with ``"memory"``, whole in
    memory (the reference the partitioned join is tested against). ``threads`` (default: one per core, at
    most 8) score chunks side by side (each side's matrices are built on at most ``LABEL_THREADS`` of them);
    the report and the outputs are the same whatever their number (chunks are summed and written in input
    order).
    """
    from ...io import TableWriter, open_table, system_metadata, write_json
    from ...io.writers import check_report_outputs
    from ...metrics.evaluate import check_protocols

    try:
        protocols = check_protocols(protocols or None)
    except ValueError as exc:
        raise HpeError(str(exc)) from None
    check_report_outputs(report, output, overwrite)
    if html:
        check_report_outputs(html, None, overwrite)
    if plots:
        from ...report.eval_plots import check_plot_outputs

        check_plot_outputs(plots, overwrite)
    from ...io.system_meta import output_system, resolve_system

    psrc = open_table(pred_path, batch_size)
    pcols = psrc.columns
    gsrc = open_table(gt_path, batch_size)
    # each side's own system (hpe:system metadata, dataset formats), else its option; a disagreeing option is a
    # usage error unless --reinterpret-as
    gres = resolve_system(gsrc, gt_system, default=None, option_name="--gt-system", option_is_output=True)
    pres = resolve_system(psrc, pred_system, default=None, option_name="--pred-system", option_is_output=True)
    gt_system, pred_system = output_system(gres), output_system(pres)
    gcols = list(gsrc.columns)
    if "file" in gcols and "image" not in gcols and getattr(gsrc, "dataset", False):
        gcols.append("image")  # the .mat folder's key: see join._stem_key_hook
    keys = choose_keys(list(keys or ()), pcols, gcols, pred_path, gt_path, join_mode)
    protocols, choice = choose_directmhp(protocols, gsrc)
    if by and by not in gcols and by not in pcols:
        raise HpeError(f"{gt_path}: --by column {by!r} is in neither table; found: {', '.join(gcols[:20])}")
    folder = images or (str(gsrc.path) if getattr(gsrc, "dataset", False) and gsrc.path.is_dir() else None)
    s = _Settings(
        pred_path=pred_path,
        gt_path=gt_path,
        pred_system=pred_system,
        gt_system=gt_system,
        keys=keys,
        protocols=protocols,
        align=align,
        by=by,
        yaw_bins=yaw_bins,
        rejects=rejects,
        use_pred=use_pred,
        use_gt=use_gt,
        radians=radians,
        overwrite=overwrite,
        batch_size=batch_size,
        progress=progress,
        strict=strict,
        join_mode=join_mode,
        orthonormalize=orthonormalize,
        html=html,
        worst=worst,
        images=Images(folder) if folder else None,
        join_engine=join_engine,
        partition_rows=partition_rows,
        threads=default_threads(threads),
    )
    meta = {
        **system_metadata(gt_system),
        "hpe:evaluate_pred_system": pred_system.name,
        "hpe:evaluate_note": "gt_* and pred_* are angles in the GT system (primary solution of each "
        "rotation; pred after --align); err_* "
        "are wrapped |pred - gt| in [0, 180]; geodesic and maev_* in degrees; frobenius "
        "unitless",
    }

    def attempt(stream):
        if output:
            with TableWriter(output, overwrite, meta) as w:
                res = _run(s, w, stream)
                if w.rows == 0:
                    w.write(empty_rows(keys))
                return res
        return _run(s, None, stream)

    try:
        out, glob, n, notes, gside, pside, rej = attempt(True)
        streamed = True
    except Unaligned:
        out, glob, n, notes, gside, pside, rej = attempt(False)
        streamed = False
    (rep, rep_before, counts, worst_rows, sample) = out
    result = _result(s, rep, rep_before, counts, n, notes, gside, pside, glob, rej, streamed)
    if choice:
        result["notes"].insert(0, choice)
    rej.write()
    if plots:
        from ...report.eval_plots import write_eval_plots

        write_eval_plots(plots, sample.rows(), result, gside.system, overwrite=overwrite)
    if html:
        from pathlib import Path

        from ...report.evaluate_page import write_page

        frame = worst_rows.frame.to_pandas() if worst_rows.frame is not None else None
        write_page(
            html,
            result,
            frame,
            overwrite=overwrite,
            plots=sample.rows(),
            pictures=worst_pictures(frame, s.images, gside.system, Path(gt_path).parent),
        )
    if report == "-":
        import sys

        from ...io.writers import json_text

        sys.stdout.write(json_text(result) + "\n")
        sys.stdout.flush()
    elif report:
        write_json(result, report, overwrite=overwrite)
    return result
