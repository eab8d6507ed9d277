"""``hpe evaluate``: pair predictions with ground truth by key, score every pair, write the outputs.

Memory is flat in the number of pairs whenever the two files list the same
keys in the same order (or ``--join order``): chunks are paired as they are
read (:func:`hpe_cli.pipelines.evaluate.lockstep.lockstep`, keys verified chunk by
chunk), every metric is summed per group (:class:`hpe_cli.metrics.stream.Accumulator`),
the geodesic errors are spilled as float32 for exact medians and percentiles,
and the per-row output is written chunk by chunk. Files in different orders
are hashed by key into partition files and joined one partition at a time
(:mod:`hpe_cli.pipelines.evaluate.spill`), then scored the same way.
``--align mean``'s offset, needed by every chunk, takes one extra pass; opal23-align, whose Karcher mean needs
every pair too, is scored after the pass from what each chunk spilled (:mod:`hpe_cli.pipelines.evaluate.opal23`).
"""

from __future__ import annotations

import sys
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import HpeError
from ...io import Rejects, TableWriter, open_table, system_metadata, write_json
from ...io.label_source import LabelSource
from ...io.writers import check_report_outputs, json_text
from ...metrics import peer_angles as pa_
from ...metrics.align import project_to_so3
from ...metrics.protocols import PROTOCOLS, PosePair, opal23_mats
from ...report.eval_plots import check_plot_outputs, write_eval_plots
from ...report.evaluate_page import write_page
from ..heap import keep_freed_memory
from ..pools import default_threads, in_order
from .dataset import choose_directmhp
from .join import choose_keys, join
from .lockstep import Unaligned, lockstep, prefetch
from .opal23 import OPAL23_ALIGN, KarcherSpill
from .options import EvaluateOptions
from .outputs import Images, empty_rows, worst_pictures
from .rejects import align_block, collect_rejects, unreadable_rejects
from .score import PLACEMENT, nested, raw_angles, score_pairs, take_rows, with_canonical
from .sides import LABEL_THREADS, Chunk, SideReader, open_side, read_side, side_columns
from .spill import Partitions

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
            None if pred.raw is None else np.take(pred.raw, pi, axis=0),  # rows of (n, 3): 4x faster than [pi]
            None if pred.dist is None else pred.dist[pi],
            None,
            None if pred.by is None else pred.by[pi],
            pred.lines[pi],
        )
        yield g, p


@dataclass
class Plan:
    """One run, decided once before any pass: the options, both sides opened once, the key columns, the protocols
    (``directmhp`` resolved to the GT dataset's variant), the pictures' folder and the thread count; and the
    readers of the pass being scored (``gside``, ``pside``: the rows set aside name their files)."""

    options: EvaluateOptions
    gt: LabelSource
    pred: LabelSource
    keys: list
    protocols: list
    images: Images | None
    threads: int
    progress: object = None
    gside: SideReader | None = None
    pside: SideReader | None = None
    partitions: int = 0


def _globals(s, pairs_factory, gsys, psys) -> dict:
    """Estimates over all pairs that every chunk's scores need: --align mean's offset (and then opal23's mean,
    over the predictions before that offset; without --align mean opal23-align is scored after the pass,
    :mod:`.opal23`)."""

    if s.options.align != "mean":
        return {}
    need_opal = OPAL23_ALIGN in s.protocols
    M, n = np.zeros((3, 3)), 0

    def work(gp):  # on a pool thread: pure numpy, no shared state
        g, p = with_canonical(gp[0], gsys), with_canonical(gp[1], psys)
        ok = g.ok & p.ok
        if not ok.all():
            g, p = take_rows(g, ok), take_rows(p, ok)
        P, G = nested(p), nested(g)
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

    karcher = KarcherSpill()
    threads = max(1, s.threads)
    pool = ThreadPoolExecutor(threads, thread_name_prefix="hpe-evaluate-glob")
    pairs = pairs_factory()
    try:
        # chunks in input order whatever the threads: the same sums, the same spill
        for rows, part, deltas, near, lines in in_order(pool, work, pairs, ahead=threads):
            for k in range(3):
                for m in range(3):
                    M[k, m] += part[k, m]
            n += rows
            if deltas is not None:
                karcher.add(deltas, near, lines)
        out = {"Q": project_to_so3(M / n) if n else np.eye(3)}
        if need_opal:
            out["opal23_mean"] = karcher.mean(mapper=pool.map)
        return out
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if hasattr(pairs, "close"):  # an error or a signal: the readers' threads and temp files go now
            pairs.close()
        karcher.close()


def _readers(s: Plan, progress=None):
    """A reader of each side for one pass (the sides were opened once: nothing is resolved again)."""
    o = s.options
    labels = min(s.threads, LABEL_THREADS)
    extra = PLACEMENT if o.html else ()
    gr = SideReader(s.gt, s.keys, o.by, o.radians, progress, extra=extra, threads=labels)
    by = o.by if o.by not in gr.columns else None
    pr = SideReader(s.pred, s.keys, by, o.radians, progress, o.orthonormalize, threads=labels)
    return gr, pr


def _run_stream(s, rej, writer):
    """Pair the chunks as they are read (same keys in the same order, or --join order)."""
    notes: set = set()

    def factory():
        gr, pr = _readers(s)
        return lockstep(gr, pr, s.keys, s.options.join_mode, set())

    gr, pr = _readers(s, s.progress)
    s.gside, s.pside = gr, pr
    glob = _globals(s, factory, gr.system, pr.system)
    out = score_pairs(
        s, prefetch(lockstep(gr, pr, s.keys, s.options.join_mode, notes)), rej, gr.system, pr.system, glob, writer, True
    )
    if s.options.join_mode == "order" and (gr.unreadable or pr.unreadable):
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
    o = s.options
    labels = min(s.threads, LABEL_THREADS)
    gt = read_side(s.gt, s.keys, o.by, o.radians, s.progress, threads=labels)
    by = o.by if o.by not in gt.columns else None
    pred = read_side(s.pred, s.keys, by, o.radians, s.progress, o.orthonormalize, threads=labels)
    if pred.n == 0 and not pred.unreadable:
        raise HpeError(f"{pred.path}: no prediction rows (the file has a header only)")
    gidx, pidx, unmatched, notes = join(pred, gt, s.keys, s.options.join_mode)

    def key_cols(side, rows):
        if s.keys:
            return {k: side.keys.column(k).take(rows).to_numpy(zero_copy_only=False) for k in s.keys}
        return {"row": rows + 1}

    valid, missing, invalid = collect_rejects(rej, gt, pred, gidx, pidx, unmatched, key_cols)
    gv, pv = gidx[valid], pidx[valid]
    glob = _globals(s, lambda: _memory_pairs(gt, pred, gv, pv, s.options.batch_size), gt.system, pred.system)
    out = score_pairs(
        s, _memory_pairs(gt, pred, gv, pv, s.options.batch_size), rej, gt.system, pred.system, glob, writer, False
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

    gr, pr = _readers(s, s.progress)
    s.gside, s.pside = gr, pr
    parts = Partitions(gr, pr, s.keys, s.options.partition_rows).fill()
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

        def joined(last: bool):  # run a partition ahead (see below): read and joined while the one before is paired
            for k in range(parts.K):
                gt, pred = parts.sides(k, last)  # the scoring pass is the last to read them
                yield gt, pred, join(pred, gt, s.keys, "key", stems, parts.codes(gt, pred, stems))

        def pairs(first: bool):
            with closing(prefetch(joined(first))) as ahead:
                yield from _partition_pairs(ahead, first)

        def _partition_pairs(ahead, first: bool):
            for gt, pred, (gidx, pidx, unmatched, nt) in ahead:
                notes.update(nt)
                if first:
                    valid, missing, invalid = collect_rejects(rej, gt, pred, gidx, pidx, unmatched, key_cols)
                    tally["missing"] += int(missing.sum())
                    tally["invalid"] += int(invalid.sum())
                    tally["unmatched_pred"] += len(unmatched)
                else:
                    valid = _valid(gt, pred, gidx, pidx)
                yield from _memory_pairs(gt, pred, gidx[valid], pidx[valid], s.options.batch_size)
                del gt, pred, gidx, pidx

        glob = _globals(s, lambda: prefetch(pairs(False)), gr.system, pr.system)
        # the next partition is read and joined on a thread while this one is paired and scored
        out = score_pairs(s, prefetch(pairs(True)), rej, gr.system, pr.system, glob, writer, False)
    finally:
        parts.cleanup()
    out[2]["invalid"] = tally["invalid"]
    n = {"gt": gr.n, "pred": pr.n, "missing": tally["missing"], "unmatched_pred": tally["unmatched_pred"]}
    s.partitions = parts.K
    return out, glob, n, sorted(notes), gr, pr


@dataclass
class Outcome:
    """What one scoring run gives: the scores, the global estimates, the counts, the notes, the readers of each
    side, the rows set aside and how the pairs were made."""

    scores: tuple  # (report, report before --align, counts, worst rows, plot sample) of score_pairs
    glob: dict
    n: dict
    notes: list
    gside: object
    pside: object
    rej: object
    streamed: bool


def _run(s: Plan, writer, stream: bool) -> Outcome:
    o = s.options
    rej = Rejects(o.rejects, o.overwrite, strict=o.strict, source=None)
    run = _run_stream if stream else (_run_memory if o.join_engine == "memory" else _run_spill)
    out, glob, n, notes, gside, pside = run(s, rej, writer)
    rej.check()  # without --rejects (or with --strict) any set-aside row is an error: nothing is written
    if pside.n == 0 and not pside.unreadable:
        raise HpeError(f"{pside.path}: no prediction rows (the file has a header only)")
    if gside.n == 0 and not gside.unreadable:
        raise HpeError(f"{gside.path}: no ground-truth rows")
    return Outcome(out, glob, n, notes, gside, pside, rej, stream)


def _counts(s: Plan, r: Outcome) -> dict:
    """The report's ``n`` block, and ``orthonormalize`` block when asked."""
    counts = r.scores[2]
    n = {
        "gt": r.n["gt"],
        "pred": r.n["pred"],
        "pairs": counts["pairs"],
        "missing": r.n["missing"],
        "invalid": counts["invalid"],
        "unmatched_pred": r.n["unmatched_pred"],
    }
    if r.gside.unreadable or r.pside.unreadable:
        n["unreadable"] = len(r.gside.unreadable) + len(r.pside.unreadable)
    if not s.options.orthonormalize:
        return {"n": n}
    n["orthonormalized"] = counts.get("orthonormalized", 0)
    ortho = {
        "method": "nearest rotation (SVD, det +1) of each prediction matrix",
        "max_distance": counts.get("dist_max"),
        "mean_distance": counts["dist_sum"] / counts["pairs"] if counts.get("pairs") and "dist_sum" in counts else None,
    }
    return {"n": n, "orthonormalize": ortho}


def _paired(s: Plan, streamed: bool) -> str:
    if streamed:
        return "streamed in file order"
    if s.options.join_engine == "memory":
        return "joined in memory"
    return f"joined by key in {s.partitions} partition(s) on disk (external hash join)"


def _result(s: Plan, r: Outcome) -> dict:
    """The report dict of one run."""
    o = s.options
    rep, rep_before = r.scores[0], r.scores[1]
    gside, pside = r.gside, r.pside
    result = _counts(s, r)
    result["systems"] = {"pred": pside.system.name, "gt": gside.system.name}
    result["system_origin"] = {"pred": pside.resolved.describe(), "gt": gside.resolved.describe()}
    if "orthonormalize" in result:  # the report's keys in their order
        result["orthonormalize"] = result.pop("orthonormalize")
    result["align"] = align_block(r.glob, rep_before, gside.system) if o.align == "mean" else {"method": "none"}
    result["metrics"], result["protocols"] = rep["metrics"], rep["protocols"]
    if o.by:
        result["by"] = {"column": o.by, "groups": rep["by_groups"]}
    if o.yaw_bins:
        result["yaw_bins"] = rep["yaw_bins"]
    result["inputs"] = {
        "pred": str(pside.path),
        "gt": str(gside.path),
        "key": s.keys or "row order",
        "join": o.join_mode,
        "paired": _paired(s, r.streamed),
        "columns": {"pred": pside.mode, "gt": gside.mode},
    }
    result["notes"] = list(r.notes) + [f"{name}: {note}" for name in s.protocols for note in PROTOCOLS[name].notes]
    if r.rej.counts:
        result["rejects"] = dict(r.rej.counts)
    return result


def _check_outputs(o: EvaluateOptions) -> None:
    """Refuse outputs that exist (without ``overwrite``) or clash, before anything is read."""
    check_report_outputs(o.report, o.output, o.overwrite)
    if o.html:
        check_report_outputs(o.html, None, o.overwrite)
    if o.plots:
        check_plot_outputs(o.plots, o.overwrite)


def plan(pred_path, gt_path, options: EvaluateOptions, progress=None) -> tuple:
    """``(Plan, note or None)``: both sides opened once (each side's own system, else its option), the key, the
    protocols (and the note saying which DirectMHP variant the GT's dataset picked)."""
    o = options
    ptable = open_table(pred_path, o.batch_size, with_lines=True)
    gtable = open_table(gt_path, o.batch_size, with_lines=True)
    gt = open_side(gtable, o.gt_system, o.use_gt, "gt")
    pred = open_side(ptable, o.pred_system, o.use_pred, "pred")
    pcols, gcols = list(pred.columns), side_columns(gt.table)  # a .mat folder of GT rows is keyed by image too
    keys = choose_keys(list(o.keys), pcols, gcols, pred_path, gt_path, o.join_mode)
    protocols, choice = choose_directmhp(list(o.protocols), gt.table)
    if o.by and o.by not in gcols and o.by not in pcols:
        raise HpeError(f"{gt_path}: --by column {o.by!r} is in neither table; found: {', '.join(gcols[:20])}")
    folder = o.images or (str(gt.path) if gt.dataset and gt.path.is_dir() else None)
    s = Plan(o, gt, pred, keys, protocols, Images(folder) if folder else None, default_threads(o.threads), progress)
    return s, choice


def _scored(s: Plan) -> Outcome:
    """Stream the two files side by side, or, when their keys are not in the same order, join them by key."""
    o = s.options
    meta = {
        **system_metadata(s.gt.output_system),
        "hpe:evaluate_pred_system": s.pred.output_system.name,
        "hpe:evaluate_note": "gt_* and pred_* are angles in the GT system (primary solution of each "
        "rotation; pred after --align); err_* "
        "are wrapped |pred - gt| in [0, 180]; geodesic and maev_* in degrees; frobenius "
        "unitless",
    }

    def attempt(stream):
        if o.output:
            with TableWriter(o.output, o.overwrite, meta) as w:
                res = _run(s, w, stream)
                if w.rows == 0:
                    w.write(empty_rows(s.keys))
                return res
        return _run(s, None, stream)

    try:
        return attempt(True)
    except Unaligned:
        return attempt(False)


def _write_outputs(s: Plan, r: Outcome, result: dict) -> None:
    """The rejects, the plots, the page and the JSON report (each side's system as read: nothing resolved again)."""
    o = s.options
    r.rej.write()
    worst_rows, sample = r.scores[3], r.scores[4]
    if o.plots:
        write_eval_plots(o.plots, sample.rows(), result, r.gside.system, overwrite=o.overwrite)
    if o.html:
        frame = worst_rows.frame.to_pandas() if worst_rows.frame is not None else None
        pictures = worst_pictures(frame, s.images, r.gside.system, Path(s.gt.path).parent)
        write_page(o.html, result, frame, overwrite=o.overwrite, plots=sample.rows(), pictures=pictures)
    if o.report == "-":
        sys.stdout.write(json_text(result) + "\n")
        sys.stdout.flush()
    elif o.report:
        write_json(result, o.report, overwrite=o.overwrite)


def run_evaluate(pred_path, gt_path, options: EvaluateOptions, *, progress=None) -> dict:
    """Evaluate ``pred_path`` against ``gt_path``; write the outputs ``options`` asks for; return the report.

    Parameters
    ----------
    pred_path, gt_path : str or Path
        Any table hpe reads (Parquet, CSV, JSON, a ``.mat`` folder, BIWI files...), each opened once.
    options : EvaluateOptions
        The run's settings (built by ``hpe evaluate`` and :func:`hpe_cli.api.evaluate_files` alike).
    progress : tqdm-like, optional
        Updated with the rows read of both sides.

    Returns
    -------
    dict
        The JSON report (``n``, ``systems``, ``metrics``, ``protocols``, ``inputs``, ``notes``...).

    Files in different orders are joined by an external hash join (``join_engine="spill"``,
    :mod:`hpe_cli.pipelines.evaluate.spill`) or, with ``"memory"``, whole in memory (the reference the
    partitioned join is tested against). ``threads`` score chunks side by side; the report and the outputs are
    the same whatever their number (chunks are summed and written in input order).
    """
    _check_outputs(options)
    keep_freed_memory()  # the chunks' freed temporaries reused, not faulted in again (pipelines.heap)
    s, choice = plan(pred_path, gt_path, options, progress)
    r = _scored(s)
    result = _result(s, r)
    if choice:
        result["notes"].insert(0, choice)
    _write_outputs(s, r, result)
    return result
