"""The views and time checks of a table sorted by (sequence, frame), group by group as the rows stream.

:class:`GroupStream` holds only the rows whose result can still change: the
frames not yet complete (views) and the last ``2 * max_gap`` frames of the
current sequence (time: a row's neighbours are at most ``max_gap`` frames away,
and a row is final once a frame more than ``max_gap`` after it was read). The
results go, in input order, to a temporary file (:class:`GroupSpill`); the
statistics to :class:`hpe_cli.metrics.sketch.StreamQuantiles`, the cameras'
median offsets to one per camera and axis. The results are those of
:mod:`hpe_cli.pipelines.audit.groups` on the whole table (tested).

:func:`sorted_by_sequence_frame` tells whether a Parquet table qualifies (one
pass over its ``sequence`` and ``frame`` columns); other tables use
:mod:`~hpe_cli.pipelines.audit.groups` on the held rows.
"""

from __future__ import annotations

import tempfile

import numpy as np
import pyarrow.parquet as pq

from ...io.layout import arrow_to_numpy
from ...metrics import consistency as mc
from ...metrics.sketch import StreamQuantiles
from .common import _codes
from .groups import MIN_VIEWS, camera_rotations, time_rates, view_groups

RESULT = np.dtype([("view", "<f8"), ("vcode", "u1"), ("jump", "<f8"), ("tcode", "u1")])


def sorted_by_sequence_frame(src) -> bool:
    """True for a Parquet table whose ``sequence`` values form one run each and whose ``frame`` never decreases
    within a run (the whole table when it has no ``sequence`` column)."""
    if src.kind != "parquet" or "frame" not in src.columns:
        return False

    cols = ["frame"] + (["sequence"] if "sequence" in src.columns else [])
    pf = pq.ParquetFile(src.path)
    if not set(cols) <= set(pf.schema_arrow.names):
        return False
    table, seen, last = {}, set(), None

    for b in pf.iter_batches(1 << 18, columns=cols):
        f = arrow_to_numpy(b.column("frame")).astype(np.int64)
        s = _codes(b.column("sequence"), table) if "sequence" in cols else np.zeros(len(f), np.int64)
        if last is not None:
            f, s = np.append(last[0], f), np.append(last[1], s)
        new_run = np.flatnonzero(s[1:] != s[:-1]) + 1
        if np.any((f[1:] < f[:-1]) & (s[1:] == s[:-1])):
            return False
        starts = s[np.concatenate([[0], new_run])] if last is None else s[new_run]
        for v in starts.tolist():
            if v in seen:
                return False
            seen.add(v)
        if last is None:
            seen.add(int(s[0]))
        last = (f[-1:], s[-1:])
    return True


class GroupSpill:
    """Per-row results of the streamed checks (:data:`RESULT`), in input order, in an unnamed temporary file."""

    def __init__(self):

        self.f = tempfile.TemporaryFile(prefix="hpe_consistency_groups_")
        self.n = 0

    def append(self, rec) -> None:
        self.f.seek(0, 2)
        self.f.write(np.ascontiguousarray(rec, dtype=RESULT).tobytes())
        self.n += len(rec)

    def read(self, off: int, n: int):
        """``(view_angle, view_code, jump_rate, time_code)`` of rows ``off .. off + n``."""
        n = max(0, min(n, self.n - off))
        self.f.seek(off * RESULT.itemsize)
        r = np.frombuffer(self.f.read(n * RESULT.itemsize), dtype=RESULT)
        return r["view"].copy(), r["vcode"].copy(), r["jump"].copy(), r["tcode"].copy()


class GroupStream:
    """Feed :meth:`add` the labels and keys of each batch in input order; :meth:`finish` flushes and summarises."""

    KEYS = ("A", "finite", "frame", "cam_R")

    def __init__(self, cons):
        self.cons = cons
        self.gap = int(cons.s.max_gap)
        self.pend = None
        self.v_done = 0  # rows of pend whose views result is final (a prefix)
        self.written = 0  # rows at the head of pend already written (kept as time neighbours only)
        self.results = GroupSpill()
        cap = cons.s.exact_rows
        self.view_q = StreamQuantiles(180.0, 0.001, cap)
        self.rate_q = StreamQuantiles(180.0, 0.001, cap)
        self.cam_q = {}  # camera code -> 3 StreamQuantiles (rotation vector, degrees)
        self.groups = self.jumps = 0

    # ----------------------------------------------------------------- streaming
    def add(self, part) -> None:
        part = {k: part[k] for k in (*self.KEYS, *self.cons.track_cols) if k in part}
        part["cam_R"] = self._cam_R(part)
        part["view"] = np.full(len(part["frame"]), np.nan)
        part["vcode"] = np.zeros(len(part["frame"]), np.uint8)
        self.pend = part if self.pend is None else {k: np.concatenate([self.pend[k], part[k]]) for k in part}
        self._step(final=False)

    def _seq(self, P):
        return P["sequence"] if "sequence" in P else np.zeros(len(P["frame"]), np.int64)

    def _step(self, final: bool) -> None:
        """Finish what the rows read so far allow; keep the rest (and the time neighbours) for later."""
        P = self.pend
        N = len(P["frame"])
        if N == 0:
            return
        seq, fr = self._seq(P), P["frame"]
        last = seq == seq[-1]
        if final:
            v_end = t_end = N
        else:  # sorted: rows of earlier sequences and of frames before the last are complete
            v_end = int(np.argmax(last & (fr >= fr[-1])))
            t_end = int(np.argmax(last & (fr >= fr[-1] - self.gap)))
        if v_end > self.v_done and not self.cons.view_reason:
            self._views(P, self.v_done, v_end)
        self.v_done = max(self.v_done, v_end)
        w = self.written
        if t_end > w:
            rate, tcode = self._time(P)
            rec = np.zeros(t_end - w, RESULT)
            rec["view"], rec["vcode"] = P["view"][w:t_end], P["vcode"][w:t_end]
            rec["jump"], rec["tcode"] = rate[w:t_end], tcode[w:t_end]
            self.results.append(rec)
            r = rate[w:t_end]
            r = r[np.isfinite(r)]
            self.rate_q.add(r)
            self.jumps += int((r > self.cons.s.max_jump_deg).sum())
            self.view_q.add(P["view"][w:t_end])
        # drop the written rows that cannot be a time neighbour of a row still to come
        k = t_end if final else min(t_end, int(np.argmax(last & (fr >= fr[-1] - 2 * self.gap))))
        self.pend = {key: v[k:] for key, v in P.items()}
        self.written = max(t_end, w) - k
        self.v_done -= k

    def _time(self, P):
        """Rates and reason codes of every held row (:func:`hpe_cli.metrics.consistency.temporal_jumps`)."""
        return time_rates(self.cons, P, P["finite"])

    def _cam_R(self, part) -> np.ndarray:
        if self.cons.view_reason:
            return np.full((len(part["frame"]), 3, 3), np.nan)
        return camera_rotations(self.cons, part["camera"], part.get("sequence"))

    def _views(self, P, lo: int, hi: int) -> None:
        """Views results of rows ``lo .. hi`` of ``P`` (complete frames), into ``P["view"]``, ``P["vcode"]``."""
        cons = self.cons
        sl = slice(lo, hi)
        have_cam = np.isfinite(P["cam_R"][sl]).all((1, 2))
        finite = P["finite"][sl]
        code = P["vcode"][sl]
        code[~have_cam] = 1
        code[~finite] = 2
        keys = [P[c][sl] for c in cons.view_cols] + [P["frame"][sl]]
        order, starts = view_groups(keys, have_cam & finite, code)
        if not len(order):
            return
        self.groups += len(starts)
        res = mc.view_consensus(P["A"][sl][order], P["cam_R"][sl][order], starts)
        P["view"][sl][order] = res["angle"]
        cams = P["camera"][sl][order]
        for c in np.unique(cams):  # cameras, not rows
            q = self.cam_q.setdefault(
                int(c), [StreamQuantiles(180.0, 0.001, self.cons.s.exact_rows, lo=-180.0) for _ in range(3)]
            )
            for k in range(3):
                q[k].add(res["offset"][cams == c, k])

    # ----------------------------------------------------------------- summaries
    def finish(self):
        """Flush; return ``(views summary, time summary)`` as :mod:`~hpe_cli.pipelines.audit.groups`."""
        if self.pend is not None:
            self._step(final=True)
        self.pend = None
        cons = self.cons
        time = {
            "tracks": [*cons.track_cols] or ["(whole table)"],
            "checked": int(self.rate_q.n),
            "jumps": self.jumps,
            "rate_deg_per_frame": self.rate_q.stats(),
        }
        if cons.view_reason:
            return {"checked": 0, "reason": cons.view_reason}, time
        cam_names = {v: k for k, v in cons.code_tables["camera"].items()}
        codes = np.array(sorted(self.cam_q), dtype=np.int64)
        cams_out, named = [], []
        if len(codes):
            med = np.array([[float(q.percentile(50)[0]) for q in self.cam_q[c]] for c in codes])
            mad = np.array([[q.mad(m) for q, m in zip(self.cam_q[c], med[i])] for i, c in enumerate(codes)])
            n = np.array([self.cam_q[c][0].n for c in codes])
            angle = np.linalg.norm(med, axis=1)
            se = 1.4826 * np.linalg.norm(mad, axis=1) / np.sqrt(n)
            sig = (angle > mc.VIEW_EXPECTED) & (angle > 3.0 * se)
            for k in np.argsort(-angle):
                entry = {
                    "camera": cam_names.get(int(codes[k])),
                    "rows": int(n[k]),
                    "offset_deg": round(float(angle[k]), 4),
                    "rotvec_deg": [round(float(v), 4) for v in med[k]],
                    "significant": bool(sig[k]),
                }
                cams_out.append(entry)
                if entry["significant"]:
                    named.append(entry["camera"])
        views = {
            "calibration": cons.calibration_files,
            "checked": int(self.view_q.n),
            "groups": int(self.groups),
            "min_views": MIN_VIEWS,
            "angle_deg": self.view_q.stats(),
            "cameras_with_offset": named,
            "cameras": cams_out,
        }
        return views, time

    def read(self, off: int, n: int):
        return self.results.read(off, n)
