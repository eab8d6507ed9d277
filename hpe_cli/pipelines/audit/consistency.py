"""``hpe audit --consistency``: each label against independent evidence, one ranking.

Three checks, each applied where its evidence exists (the maths is in
:mod:`hpe_cli.geometry.landmark_pose` and :mod:`hpe_cli.metrics.consistency`):

landmarks
    Rows with 2-D landmark columns ``lm{i}_x, lm{i}_y`` (21: aflw21, 68: ibug68,
    70: face70), or a 300W-LP/AFLW2000 ``.mat`` folder (its ``pt2d``): the
    weak-perspective rotation of the 68-point mean face fitted to them, and its
    angle to the label.
views
    Rows with ``camera``, ``frame`` (and ``person_id``, ``sequence`` when present) and
    a Panoptic calibration (``--calibration``, or the one ``hpe relabel-panoptic``
    recorded in the table's metadata): each label mapped back to the world and
    compared with the robust consensus of the labels of that head at that frame;
    each camera's median offset.
time
    Rows with a ``frame`` column (tracks: ``sequence``, ``person_id``, ``camera``
    when present): a label that leaves the interpolation of its neighbours by more
    than ``max_jump`` degrees per frame.

Rows none of the checks applies to are "not checked", with the reasons, never
consistent. Memory: a few numbers per row (the label matrix only when the table
has a ``frame`` column), the landmarks of one batch at a time.
"""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ...datasets.mat import read_mat_dir
from ...datasets.panoptic_calibration import read_calibration
from ...errors import HpeError
from ...geometry.landmark_pose import (
    FIT_REASONS,
    MIN_POINTS,
    SCHEME_SIZES,
    fit_landmark_pose,
    fit_landmark_pose_perspective,
)
from ...io import write_table
from ...io.layout import arrow_to_numpy, landmark_count
from ...metrics import consistency as mc
from ...metrics.sketch import StreamQuantiles
from ...rotation.distances import geodesic_deg
from .common import _codes, _key_batches, _r, canonical_labels, suspects_table  # noqa: F401
from .groups import MIN_VIEWS, time_check, time_texts, view_texts, views  # noqa: F401 (re-exported)
from .options import MAX_GAP_FRAMES, MAX_JUMP_DEG, Settings  # noqa: F401 (re-exported)
from .spill import RowSpill
from .stream import GroupStream, sorted_by_sequence_frame

#: a landmark fit whose residual (per inter-ocular distance) is above this does not look like a face
MAX_RESIDUAL = 0.35
#: landmark reason codes after the fit's own (:data:`hpe_cli.geometry.landmark_pose.FIT_REASONS`)
LM_POOR, LM_NOT_FINITE, LM_NONE = len(FIT_REASONS), len(FIT_REASONS) + 1, len(FIT_REASONS) + 2
LM_TEXTS = (
    *FIT_REASONS,
    f"landmarks do not fit the face model (residual > {MAX_RESIDUAL} inter-ocular)",
    "label not finite",
    "no landmark columns",
)
#: ID columns reported for suspects (those present, in this order)
KEY_COLUMNS = ("file", "image", "image_id", "id", "path", "sequence", "frame", "camera", "person_id")

MODEL = "DirectMHP's 68-point mean face (hpe_cli/data/reference_3d_68_points_trans.npy), weak perspective"
POINTS = {
    "ibug68": "iBUG-68 inner points 17-67 (the jaw contour 0-16 is not used)",
    "face70": "face70 inner points 17-67 and the pupils 68, 69",
    "aflw21": "AFLW-21 points except the ears (12, 16), mapped to iBUG-68 points",
}

#: output columns added to ``hpe audit -o``
COLUMNS = (
    "landmark_angle",
    "landmark_residual",
    "view_angle",
    "jump_rate",
    "consistency_score",
    "suspect",
    "consistency_note",
)


def _relabel_meta(src) -> dict:
    md = getattr(src.schema, "metadata", None) or {}
    raw = md.get(b"hpe:relabel")
    try:
        return json.loads(raw) if raw else {}
    except ValueError:
        return {}


class ConsistencyAudit:
    """Collects the evidence batch by batch (:meth:`add`), then ranks (:meth:`finish`).

    Memory is flat in rows for tables without a ``frame`` column: each row's
    numbers go to a temporary file (:mod:`hpe_cli.pipelines.audit.spill`,
    61 bytes a row on disk); statistics are exact up to ``exact_cap`` rows
    (``Settings.exact_rows``, :data:`hpe_cli.metrics.sketch.EXACT_CAP`), then histograms (resolution in the
    JSON). Tables with a ``frame`` column also hold each row's label matrix and
    keys (about 100 bytes a row) for the views and time checks.
    """

    def __init__(self, src, settings: Settings | None = None):
        self.src = src
        self.s = settings if isinstance(settings, Settings) else Settings()  # True: the defaults
        cols = set(src.columns)

        self.n_lm = landmark_count(src.columns)
        self.mat_landmarks = None
        if self.n_lm == 0 and src.path.is_dir() and any(src.path.glob("*.mat")):
            t = read_mat_dir(src.path, landmarks=True)
            n = sum(1 for c in t.columns if c.startswith("lm") and c.endswith("_x") and not c.startswith("lm3d"))
            if n:
                self.mat_landmarks = np.stack(
                    [t[[f"lm{i}_x" for i in range(n)]].to_numpy(), t[[f"lm{i}_y" for i in range(n)]].to_numpy()], -1
                )
                self.n_lm = n
        self.scheme = None
        if self.n_lm:
            self.scheme = next((k for k, v in SCHEME_SIZES.items() if v == self.n_lm), None)
            if self.scheme is None:
                raise HpeError(
                    f"{src.path}: expected 21 (aflw21), 68 (ibug68) or 70 (face70) landmark columns "
                    f"lm0_x..lm{{n-1}}_y for --consistency, got {self.n_lm}"
                )
        self.has_frame = "frame" in cols
        self.track_cols = [c for c in ("sequence", "person_id", "camera") if c in cols]
        self.view_cols = [c for c in ("sequence", "person_id") if c in cols]
        self.meta = _relabel_meta(src)
        self.view_reason = self._view_setup(cols)
        self.code_tables = {c: {} for c in ("sequence", "person_id", "camera")}
        self.parts = []
        self.unread = 0
        self.exact_cap = self.s.exact_rows
        self.spill = RowSpill()
        self.expected_sketch = mc.expected_angle_sketch(self.exact_cap)
        self.stream = None
        if self.has_frame and self.s.stream_groups:
            if sorted_by_sequence_frame(src):
                self.stream = GroupStream(self)

    # ------------------------------------------------------------------ set-up
    def _view_setup(self, cols) -> str:
        """Why the views check cannot run ('' when it can); loads the calibration."""
        self.cams = {}
        if not ({"camera", "frame"} <= cols):
            return "no camera and frame columns"
        if "Q.T" in str(self.meta.get("label", "")):
            return "labels in the crop frame (--frame crop)"
        paths = {}
        if self.s.calibration:
            paths[None] = self.s.calibration
        elif self.meta.get("calibration"):
            paths[None] = self.meta["calibration"]
        elif self.meta.get("calibrations"):
            paths = dict(zip(self.meta.get("sequences", []), self.meta["calibrations"]))
        if not paths:
            return "no calibration (give --calibration FILE)"

        for seq, p in paths.items():
            try:
                cams = read_calibration(p)
            except (OSError, HpeError) as exc:
                why = str(exc).removeprefix(f"{p}: ")
                raise HpeError(
                    f"{p}: cannot read the calibration for --consistency: {why} (give --calibration FILE)"
                ) from None
            self.cams[seq] = {str(n): (R, K, d) for n, R, K, d in zip(cams.names, cams.R, cams.K, cams.dist)}
        self.calibration_files = sorted(map(str, paths.values()))
        return ""

    # ------------------------------------------------------------------ pass 1
    output_columns = COLUMNS

    @staticmethod
    def output_types() -> dict:

        return {
            c: pa.bool_() if c == "suspect" else pa.string() if c == "consistency_note" else pa.float32()
            for c in COLUMNS
        }

    def add(self, batch, lines, A, part=None, unread: int = 0) -> None:
        """One batch, in input order: its ``__line__`` numbers and labels as canonical matrices ``(n, 3, 3)``.

        ``part``: :meth:`measure`'s result when a worker thread already made it.
        ``unread``: rows of the batch's block the reader could not parse (counted as not checked).
        """
        self.unread += unread
        if part is None:
            part = self.measure(batch, A, lines)
        rec = part.pop("rec")
        rec["line"] = lines
        self.spill.append(rec)
        self.expected_sketch.add(np.minimum(rec["abs_yaw"], 90.0), rec["lm_angle"])
        if self.has_frame:  # the views and time checks need the groups: labels and keys of every row
            for c in self.track_cols:
                part[c] = _codes(part[c], self.code_tables[c])
            if self.stream is not None:  # sorted by (sequence, frame): group by group
                self.stream.add(part)
            else:
                self.parts.append(part)

    def measure(self, batch, A, lines=None):
        """The per-row evidence of one batch (thread-safe; None for a .mat folder without ``lines``).

        ``A``: the labels as canonical matrices ``(n, 3, 3)``, NaN where unusable.
        Returns ``{"rec": records}`` (:data:`~hpe_cli.pipelines.audit.spill.RECORD`,
        ``line`` not yet set), plus the labels and keys of a table with a ``frame`` column.
        """
        if self.mat_landmarks is not None and lines is None:
            return None
        n = batch.num_rows
        A = np.asarray(A, dtype=np.float64).reshape(n, 3, 3)
        finite = np.isfinite(A).all((1, 2))
        rec = RowSpill.empty(n)
        rec["abs_yaw"] = np.abs(mc.yaw_deg(A))
        rec["A"] = A.reshape(n, 9)
        if self.scheme is not None:
            uv = self._landmarks(batch, lines)
            K, dist = self._intrinsics(batch)
            if K is None:
                fit = fit_landmark_pose(uv, self.scheme, reasons=False)
            else:  # calibrated cameras: corrected for the head's place in the image
                fit = fit_landmark_pose_perspective(uv, self.scheme, K, dist, reasons=False)

            lm_angle = geodesic_deg(np.where(finite[:, None, None], A, np.nan), fit["A"])
            lm_res = fit["residual"]
            code = fit["code"]  # FIT_REASONS: 0 fitted, 1 too few points, 2 degenerate
            poor = (code == 0) & ~(lm_res <= MAX_RESIDUAL)
            code[poor] = LM_POOR
            lm_angle[poor] = np.nan
            rec["lm_res"] = lm_res
            rec["F"] = fit["A"].reshape(n, 9)
        else:
            lm_angle = np.full(n, np.nan)
            rec["lm_res"] = np.nan
            rec["F"] = np.nan
            code = np.full(n, LM_NONE, dtype=np.uint8)
        code[~finite] = LM_NOT_FINITE
        lm_angle[~finite] = np.nan
        rec["lm_angle"] = lm_angle
        rec["lm_code"] = code
        part = {"rec": rec}
        if self.has_frame:
            part["finite"] = finite
            part["A"] = A
            part["frame"] = arrow_to_numpy(batch.column("frame")).astype(np.int64)
            for c in self.track_cols:
                part[c] = batch.column(c)  # coded in input order by add (one dictionary per column)
        return part

    def _intrinsics(self, batch):
        """``K`` (n, 3, 3) and ``dist`` (n, 5) of each row's camera, or ``(None, None)``.

        Rows whose camera is not in the calibration get the plain weak-perspective fit
        (an identity ``K``, pixels as they are).
        """
        if not self.cams or "camera" not in batch.schema.names:
            return None, None

        n = batch.num_rows
        cols = ["camera"] + (["sequence"] if None not in self.cams and "sequence" in batch.schema.names else [])
        codes, values = [], []
        for c in cols:
            enc = pc.dictionary_encode(batch.column(c).cast("string"))
            values.append(enc.dictionary.to_pylist() + [None])
            codes.append(enc.indices.fill_null(len(values[-1]) - 1).to_numpy(zero_copy_only=False))
        pairs, inverse = np.unique(np.stack(codes, 1), axis=0, return_inverse=True)
        Ks = np.tile(np.eye(3), (len(pairs), 1, 1))
        ds = np.zeros((len(pairs), 5))
        for j, pair in enumerate(pairs):  # one per distinct camera (and sequence) of the batch
            name = values[0][pair[0]]
            table = (
                self.cams[None]
                if None in self.cams
                else self.cams.get(values[1][pair[1]] if len(cols) > 1 else None, {})
            )
            cam = table.get(name)
            if cam is not None:
                Ks[j], ds[j] = cam[1], cam[2]
        inverse = inverse.reshape(n)
        return Ks[inverse], ds[inverse]

    def _landmarks(self, batch, lines) -> np.ndarray:
        if self.mat_landmarks is not None:
            return self.mat_landmarks[np.asarray(lines, dtype=np.int64) - 1]

        n = batch.num_rows
        cols = [arrow_to_numpy(batch.column(f"lm{i}_{a}"), np.float64) for i in range(self.n_lm) for a in "xy"]
        uv = np.empty((n, 2 * self.n_lm))  # the fit's (n, L, 2) layout (a (2, L, n) one fits 2x slower)
        for s in range(0, n, 1024):  # blocks of rows that stay in cache while their columns are interleaved
            blk = uv[s : s + 1024]
            for j, c in enumerate(cols):
                blk[:, j] = c[s : s + 1024]
        return uv.reshape(n, self.n_lm, 2)

    # ------------------------------------------------------------------ ranking
    def finish(self) -> dict:
        """Run the views and time checks, score every row; return the JSON section (without ``worst``).

        The rows are streamed back from the spill in chunks: what stays in memory is
        the suspects' numbers (sparse), the landmark statistics (exact up to
        :data:`~hpe_cli.metrics.sketch.EXACT_CAP` rows, histograms beyond) and, for
        tables with a ``frame`` column, the views and time results per row.
        """
        self.expected = mc.fit_expected_streamed(self.expected_sketch)
        self.expected_sketch = None
        N = self.spill.n
        self.N = N
        out = self._group_checks()
        lm_stats = StreamQuantiles(180.0, 0.001, self.exact_cap)
        res_stats = StreamQuantiles(MAX_RESIDUAL, 1e-5, self.exact_cap)
        self.sketches = {  # for the page's histograms
            "landmark_angle": lm_stats,
            "view_angle": StreamQuantiles(180.0, 0.001, self.exact_cap),
            "consistency_score": StreamQuantiles(200.0, 0.002, self.exact_cap),
        }
        lm_counts = np.zeros(256, np.int64)
        lm_first = np.full(256, np.iinfo(np.int64).max)
        combos = {}  # not-checked (landmarks, views, time) code triple -> [rows, first row]
        sus = []
        checked = 0
        for off, rec in self.spill.chunks():
            sc = self._score(rec, off)
            lm_ok = np.isfinite(sc["lm_angle32"])
            lm_stats.add(sc["lm_angle32"][lm_ok])
            res_stats.add(rec["lm_res"][lm_ok])
            self.sketches["view_angle"].add(sc["view_angle"].astype(np.float32))
            self.sketches["consistency_score"].add(sc["score"])
            miss = np.flatnonzero(~np.isfinite(rec["lm_angle"]))
            np.add.at(lm_counts, rec["lm_code"][miss], 1)
            np.minimum.at(lm_first, rec["lm_code"][miss], miss + off)
            checked += int(sc["checked"].sum())
            un = np.flatnonzero(~sc["checked"])
            key = (rec["lm_code"][un].astype(np.int64) * 256 + sc["view_code"][un]) * 256 + sc["time_code"][un]
            keys, first, cnt = np.unique(key, return_index=True, return_counts=True)
            for k_, f_, c_ in zip(keys.tolist(), first.tolist(), cnt.tolist()):  # distinct reasons, not rows
                e = combos.setdefault(k_, [0, int(un[f_]) + off])
                e[0] += c_
            j = np.flatnonzero(sc["suspect"])
            if len(j):
                sus.append({k_: v[j] for k_, v in sc.items() if k_ not in ("checked", "suspect")} | {"idx": j + off})
        sk = ["idx", "line", "score", "lm_angle", "lm_ratio", "view_angle", "jump", "lm_angle32"]
        self.sus = {k_: np.concatenate([p[k_] for p in sus]) for k_ in sk} if sus else None
        n_sus = 0 if self.sus is None else len(self.sus["idx"])
        reasons = Counter()
        for key, (c_, _) in sorted(combos.items(), key=lambda kv: kv[1][1]):  # first seen first
            lm_c, rest = divmod(key, 256 * 256)
            v_c, t_c = divmod(rest, 256)
            reasons[self._unchecked_text(lm_c, v_c, t_c)] += c_
        unread = self.unread
        if unread:
            reasons["not checked: label not readable"] += unread
        seen = np.flatnonzero(lm_counts)
        lm_reasons = {LM_TEXTS[c]: int(lm_counts[c]) for c in seen[np.argsort(lm_first[seen], kind="stable")]}
        report = {
            "rows": int(N) + unread,
            "checked": checked,
            "not_checked": int(N - checked) + unread,
            "not_checked_reasons": dict(reasons.most_common(10)),
            "suspects": n_sus,
            "settings": {
                "suspect_score": self.s.suspect_score,
                "score": "largest of: landmark angle / expected(|yaw|), view angle / "
                f"{mc.VIEW_EXPECTED} deg, jump rate / ({self.s.max_jump_deg} / {self.s.suspect_score}) deg per frame",
                "landmark_expected_deg": f"{self.expected['a']:.3g} + {self.expected['b']:.3g} * (|yaw| / 90)^2 "
                f"({self.expected['source']})",
                "max_jump_deg_per_frame": self.s.max_jump_deg,
                "max_gap_frames": self.s.max_gap,
            },
            "landmarks": {
                "scheme": self.scheme,
                "model": MODEL,
                "points": POINTS.get(self.scheme),
                "min_points": MIN_POINTS,
                "checked": int(lm_stats.n),
                "angle_deg": lm_stats.stats(),
                "residual": res_stats.stats(),
                "not_checked_reasons": dict(Counter(lm_reasons).most_common(10)),
            },
            **out,
        }
        if "views" not in report:
            report["views"] = {"checked": 0, "reason": self.view_reason}
        if "time" not in report:
            report["time"] = {"checked": 0, "reason": "no frame column"}
        return report

    def _group_checks(self) -> dict:
        """The views and time checks over the whole table (or the streamed groups): their JSON sections."""
        out = {}
        self.group_res = None
        if self.stream is not None:
            out["views"], out["time"] = self.stream.finish()
            self.group_res = self.stream
        elif self.has_frame and self.N:
            # one key at a time, each part's array released once concatenated: the rows are not held twice
            P = {k: np.concatenate([p.pop(k) for p in self.parts]) for k in ["A", "finite", "frame", *self.track_cols]}
            self.parts = []
            view_angle, view_code, out["views"] = views(self, P, P["finite"])
            jump, time_code, out["time"] = time_check(self, P, P["finite"])
            del P
            self.group_res = (view_angle, view_code, jump, time_code)
        return out

    def _score(self, rec, off: int) -> dict:
        """Scores of the spilled rows ``rec`` (global rows ``off ..``): ratios, score, suspect, codes."""
        n = len(rec)
        lm_angle = rec["lm_angle"]
        lm_ratio = lm_angle / mc.expected_landmark_angle(rec["abs_yaw"], self.expected["a"], self.expected["b"])
        if isinstance(self.group_res, tuple):
            va, vc, ju, tc = (a[off : off + n] for a in self.group_res)
        elif self.group_res is not None:  # streamed: read back from its file
            va, vc, ju, tc = self.group_res.read(off, n)
        else:
            va, ju = np.full(n, np.nan), np.full(n, np.nan)
            vc, tc = np.zeros(n, np.uint8), np.zeros(n, np.uint8)
        time_ratio = ju / (self.s.max_jump_deg / self.s.suspect_score)
        score = mc.combined_score(lm_ratio, va / mc.VIEW_EXPECTED, time_ratio)
        f32 = np.float32
        return {
            "line": rec["line"],
            "lm_angle": lm_angle,
            "lm_angle32": lm_angle.astype(f32),
            "lm_ratio": lm_ratio,
            "view_angle": va,
            "jump": ju,
            "view_code": vc,
            "time_code": tc,
            "score": score.astype(f32),
            "suspect": score > self.s.suspect_score,
            "checked": np.isfinite(score),
        }

    def _unchecked_text(self, lm_code, view_code, time_code) -> str:
        v = view_texts(self.view_reason or "")[view_code]
        t = time_texts(self.has_frame, self.s.max_gap)[time_code]
        return f"not checked: landmarks: {LM_TEXTS[lm_code]}; views: {v}; time: {t}"

    def _why(self, lm_angle, lm_ratio, view_angle, jump) -> str:
        parts = []
        if lm_ratio > self.s.suspect_score:
            parts.append(f"landmarks {lm_angle:.1f} deg from the label")
        if view_angle / mc.VIEW_EXPECTED > self.s.suspect_score:
            parts.append(f"views: {view_angle:.1f} deg from the consensus of its views")
        if jump * self.s.suspect_score / self.s.max_jump_deg > self.s.suspect_score:
            parts.append(f"time: jumps {jump:.1f} deg per frame away from its neighbours and back")
        return "; ".join(parts)

    def _notes(self, sc, rec) -> np.ndarray:
        """``consistency_note`` of scored rows: the suspects' reasons, the not-checked reasons, else ""."""
        out = np.full(len(rec), "", dtype=object)
        for i in np.flatnonzero(sc["suspect"]):  # suspects only
            out[i] = self._why(sc["lm_angle"][i], sc["lm_ratio"][i], sc["view_angle"][i], sc["jump"][i])
        un = np.flatnonzero(~sc["checked"])
        if len(un):
            key = (rec["lm_code"][un].astype(np.int64) * 256 + sc["view_code"][un]) * 256 + sc["time_code"][un]
            keys, inv = np.unique(key, return_inverse=True)
            texts = [self._unchecked_text(k // 65536, (k // 256) % 256, k % 256) for k in keys.tolist()]
            out[un] = np.array(texts, dtype=object)[inv.reshape(-1)]
        return out

    # ------------------------------------------------------------------ outputs
    def columns(self, offset: int, n: int) -> dict:
        """The output columns of rows ``offset .. offset + n`` (in input order), read back from the spill."""
        rec = self.spill.read(offset, n)
        sc = self._score(rec, offset)
        f32 = np.float32
        return {
            "landmark_angle": sc["lm_angle32"],
            "landmark_residual": rec["lm_res"].astype(f32),
            "view_angle": sc["view_angle"].astype(f32),
            "jump_rate": sc["jump"].astype(f32),
            "consistency_score": sc["score"],
            "suspect": sc["suspect"],
            "consistency_note": self._notes(sc, rec),
        }

    def row(self, i: int) -> dict:
        """One row's ``line``, ``score``, ``note``, ``landmark_angle``, label ``A`` and landmark fit ``F`` (3, 3)."""
        rec = self.spill.read(int(i), 1)
        sc = self._score(rec, int(i))
        F = rec["F"][0].astype(np.float64).reshape(3, 3)
        return {
            "line": int(rec["line"][0]),
            "score": float(sc["score"][0]),
            "note": str(self._notes(sc, rec)[0]),
            "landmark_angle": float(sc["lm_angle32"][0]),
            "A": rec["A"][0].astype(np.float64).reshape(3, 3),
            "F": F if np.isfinite(F).all() else None,
        }

    def worst_order(self) -> np.ndarray:
        """Row indices of the suspects, highest score first."""
        if self.sus is None:
            return np.zeros(0, np.int64)
        return self.sus["idx"][np.argsort(-self.sus["score"], kind="stable")]

    def describe_rows(self, batches, idx, key_cols) -> list:
        """``{row, key columns..., score, reason}`` of the suspects ``idx`` (global indices), read from ``batches``."""
        idx = np.asarray(idx, dtype=np.int64)
        out = [None] * len(idx)
        if not len(idx):
            return out
        at = np.searchsorted(self.sus["idx"], idx)  # the suspects' numbers (sorted by row)
        order = np.argsort(idx, kind="stable")
        srt = idx[order]
        offset = 0
        for batch in batches:
            n = batch.num_rows
            lo, hi = np.searchsorted(srt, [offset, offset + n])
            if hi > lo:
                ks = order[lo:hi]
                sub = batch.select(key_cols).take(srt[lo:hi] - offset).to_pylist()
                for k, rec in zip(ks.tolist(), sub):
                    a = at[k]
                    S = self.sus
                    out[k] = {
                        "row": int(S["line"][a]),
                        **rec,
                        "score": round(float(S["score"][a]), 3),
                        "landmark_angle": _r(S["lm_angle32"][a]),
                        "view_angle": _r(np.float32(S["view_angle"][a])),
                        "jump_rate": _r(np.float32(S["jump"][a])),
                        "reason": self._why(S["lm_angle"][a], S["lm_ratio"][a], S["view_angle"][a], S["jump"][a]),
                    }
            offset += n
        return out


def consistency_outputs(cons, reread, suspects=None, overwrite=False, plots=None, images=None) -> dict:
    """Finish ``cons``, describe its worst rows (read again with ``reread()``), write the suspects list
    and, with ``plots``, the page ``plots/consistency/index.html`` with the worst rows drawn.

    Returns the JSON section: counts, the checks' summaries, ``worst`` (the
    ``cons.s.worst`` highest-scoring suspects).
    """
    report = cons.finish()
    key_cols = [c for c in KEY_COLUMNS if c in cons.src.columns]
    order = cons.worst_order()
    top = order[: cons.s.worst]
    report["worst"] = cons.describe_rows(_key_batches(cons, reread, key_cols), top, key_cols)
    if suspects:
        table = suspects_table(cons, _key_batches(cons, reread, key_cols), order, key_cols)
        write_table(table, suspects, overwrite=overwrite)
        report["suspects_file"] = str(suspects)
    if plots:
        from ..draw.consistency import FOLDER, consistency_page  # lazy: pandas and OpenCV, only with --plots

        pics = consistency_page(cons, report, reread(), top[: cons.s.drawn], plots, images, overwrite)
        report["page"] = f"{plots}/{FOLDER}/index.html"
        report["not_drawn"] = [f"{w}: {r}" for w, r in pics["missing"]]
    return report
