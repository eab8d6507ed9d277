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
from dataclasses import dataclass

import numpy as np

from ..errors import HpeError
from ..geometry.landmark_pose import MIN_POINTS, SCHEME_SIZES, fit_landmark_pose, fit_landmark_pose_perspective
from ..metrics import consistency as mc
from .consistency_notes import _Notes, _r, _reason_codes, _stats, suspects_table

#: a landmark fit whose residual (per inter-ocular distance) is above this does not look like a face
MAX_RESIDUAL = 0.35
#: default threshold of the time check, degrees per frame
MAX_JUMP_DEG = 5.0
#: neighbours further apart than this many frames are not compared
MAX_GAP_FRAMES = 10
#: views of one head at one frame needed for a consensus
MIN_VIEWS = 3
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


@dataclass
class Settings:
    """Thresholds of the checks (see the module constants)."""

    calibration: str | None = None
    max_jump_deg: float = MAX_JUMP_DEG
    max_gap: int = MAX_GAP_FRAMES
    suspect_score: float = mc.SUSPECT_SCORE
    worst: int = 20
    drawn: int = 12


def _codes(col, table: dict) -> np.ndarray:
    """Global integer codes of an Arrow column's values (strings or ints), via dictionary encoding."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if pa.types.is_integer(col.type):
        from ..io.layout import arrow_to_numpy

        return arrow_to_numpy(col).astype(np.int64)
    enc = pc.dictionary_encode(col.cast(pa.string()))
    values = enc.dictionary.to_pylist()
    remap = np.array([table.setdefault(v, len(table)) for v in values] + [-1], dtype=np.int64)
    idx = enc.indices.fill_null(len(values)).to_numpy(zero_copy_only=False)
    return remap[idx]


def _relabel_meta(src) -> dict:
    md = getattr(src.schema, "metadata", None) or {}
    raw = md.get(b"hpe:relabel")
    try:
        return json.loads(raw) if raw else {}
    except ValueError:
        return {}


class ConsistencyAudit:
    """Collects the evidence batch by batch (:meth:`add`), then ranks (:meth:`finish`)."""

    def __init__(self, src, settings: Settings | None = None):
        self.src = src
        self.s = settings if isinstance(settings, Settings) else Settings()  # True: the defaults
        cols = set(src.columns)
        from ..io.layout import landmark_count

        self.n_lm = landmark_count(src.columns)
        self.mat_landmarks = None
        if self.n_lm == 0 and src.path.is_dir() and any(src.path.glob("*.mat")):
            from ..datasets.mat import read_mat_dir

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
        from ..datasets.panoptic_calibration import read_calibration

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
        import pyarrow as pa

        return {
            c: pa.bool_() if c == "suspect" else pa.string() if c == "consistency_note" else pa.float32()
            for c in COLUMNS
        }

    def add(self, batch, lines, A, part=None, unread: int = 0) -> None:
        """One batch, in input order: its ``__line__`` numbers and labels as canonical matrices ``(n, 3, 3)``.

        ``part``: :meth:`measure`'s result when a worker thread already made it.
        ``unread``: rows of the batch's block the reader could not parse (counted as not checked).
        """
        self.unread = getattr(self, "unread", 0) + unread
        if part is None:
            part = self.measure(batch, A, lines)
        part["line"] = np.asarray(lines, dtype=np.int64)
        self.parts.append(part)

    def measure(self, batch, A, lines=None):
        """The per-row evidence of one batch (thread-safe; None for a .mat folder without ``lines``).

        ``A``: the labels as canonical matrices ``(n, 3, 3)``, NaN where unusable.
        """
        if self.mat_landmarks is not None and lines is None:
            return None
        n = batch.num_rows
        A = np.asarray(A, dtype=np.float64).reshape(n, 3, 3)
        finite = np.isfinite(A).all((1, 2))
        part = {"finite": finite}
        part["abs_yaw"] = np.abs(mc.yaw_deg(A)).astype(np.float32)
        lm_angle = np.full(n, np.nan)
        lm_res = np.full(n, np.nan)
        lm_reason = np.full(n, "no landmark columns", dtype=object)
        if self.scheme is not None:
            uv = self._landmarks(batch, lines)
            K, dist = self._intrinsics(batch)
            if K is None:
                fit = fit_landmark_pose(uv, self.scheme)
            else:  # calibrated cameras: corrected for the head's place in the image
                fit = fit_landmark_pose_perspective(uv, self.scheme, K, dist)
            from ..rotation.distances import geodesic_deg

            lm_angle = geodesic_deg(np.where(finite[:, None, None], A, np.nan), fit["A"])
            lm_res = fit["residual"]
            lm_reason = fit["reason"].copy()
            poor = (lm_reason == "") & ~(lm_res <= MAX_RESIDUAL)
            lm_reason[poor] = f"landmarks do not fit the face model (residual > {MAX_RESIDUAL} inter-ocular)"
            lm_angle[poor] = np.nan
            # the label and the fit of rows that could be drawn among the worst (sparse: flat memory)
            with np.errstate(invalid="ignore"):
                keep = np.flatnonzero(
                    (lm_angle / mc.expected_landmark_angle(np.abs(mc.yaw_deg(A))) > 1.0) | self.has_frame
                )
            part["pic"] = (keep, A[keep].astype(np.float32), fit["A"][keep].astype(np.float32))
        lm_reason[~finite] = "label not finite"
        lm_angle[~finite] = np.nan
        part.update(lm_angle=lm_angle, lm_res=lm_res, lm_reason=lm_reason)
        if self.has_frame:
            from ..io.layout import arrow_to_numpy

            part["A"] = A
            part["frame"] = arrow_to_numpy(batch.column("frame")).astype(np.int64)
            for c in self.track_cols:
                part[c] = batch.column(c)  # coded in input order by finish (one dictionary per column)
        return part

    def _intrinsics(self, batch):
        """``K`` (n, 3, 3) and ``dist`` (n, 5) of each row's camera, or ``(None, None)``.

        Rows whose camera is not in the calibration get the plain weak-perspective fit
        (an identity ``K``, pixels as they are).
        """
        if not self.cams or "camera" not in batch.schema.names:
            return None, None
        import pyarrow.compute as pc

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
        from ..io.layout import arrow_to_numpy

        n = batch.num_rows
        uv = np.empty((n, self.n_lm, 2))
        for i in range(self.n_lm):  # columns, not rows
            for k, a in enumerate("xy"):
                uv[:, i, k] = arrow_to_numpy(batch.column(f"lm{i}_{a}"), np.float64)
        return uv

    # ------------------------------------------------------------------ ranking
    def finish(self) -> dict:
        """Run the views and time checks, score every row; return the JSON section (without ``worst``)."""
        for p in self.parts:
            for c in self.track_cols if self.has_frame else ():
                if not isinstance(p[c], np.ndarray):
                    p[c] = _codes(p[c], self.code_tables[c])
        P = {k: np.concatenate([p[k] for p in self.parts]) if self.parts else np.zeros(0) for k in self.parts_keys()}
        # rows with a landmark angle above the expected one: global index, label, landmark fit (for pictures)
        idx, la, fa, offset = [np.zeros(0, np.int64)], [np.zeros((0, 3, 3))], [np.zeros((0, 3, 3))], 0
        for p in self.parts:
            if "pic" in p:
                j, a, b = p.pop("pic")
                idx.append(j + offset)
                la.append(a)
                fa.append(b)
            offset += len(p["line"])
        self.pic = (np.concatenate(idx), np.concatenate(la), np.concatenate(fa))
        self.parts = []  # concatenated into P: do not hold the rows twice
        N = len(P["line"])
        self.N = N
        lm_angle, lm_reason = P["lm_angle"], P["lm_reason"]
        self.expected = mc.fit_expected_landmark_angle(P["abs_yaw"], lm_angle)
        lm_ratio = lm_angle / mc.expected_landmark_angle(P["abs_yaw"], self.expected["a"], self.expected["b"])
        view_angle = np.full(N, np.nan)
        view_reason = np.full(N, self.view_reason or "", dtype=object)
        jump = np.full(N, np.nan)
        time_reason = np.full(N, "no frame column" if not self.has_frame else "", dtype=object)
        out = {}
        if self.has_frame and N:
            finite = P["finite"]
            view_angle, view_reason, out["views"] = self._views(P, view_reason, finite)
            jump, time_reason, out["time"] = self._time(P, finite)
        time_ratio = jump / (self.s.max_jump_deg / self.s.suspect_score)
        view_ratio = view_angle / mc.VIEW_EXPECTED
        score = mc.combined_score(lm_ratio, view_ratio, time_ratio)
        suspect = score > self.s.suspect_score
        checked = np.isfinite(score)
        sus_idx = np.flatnonzero(suspect)
        sus_txt = [self._why(i, lm_angle, lm_ratio, view_angle, jump) for i in sus_idx]  # suspects only
        unchecked = np.flatnonzero(~checked)
        codes, texts = _reason_codes(lm_reason[unchecked], view_reason[unchecked], time_reason[unchecked])
        note = _Notes(N, sus_idx, sus_txt, unchecked, codes, texts)
        f32 = np.float32  # the ranking keeps about 30 bytes per row
        self.rows = {
            "line": P["line"],
            "landmark_angle": lm_angle.astype(f32),
            "landmark_residual": P["lm_res"].astype(f32),
            "view_angle": view_angle.astype(f32),
            "jump_rate": jump.astype(f32),
            "consistency_score": score.astype(f32),
            "suspect": suspect,
            "consistency_note": note,
        }
        lm_reasons = dict(Counter(lm_reason[~np.isfinite(lm_angle)].tolist()).most_common(10))
        del P, lm_reason, view_reason, time_reason, lm_ratio
        lm_angle = self.rows["landmark_angle"]
        lm_ok = np.isfinite(lm_angle)
        reasons = Counter({texts[k]: int(c) for k, c in zip(*np.unique(codes, return_counts=True))})
        unread = getattr(self, "unread", 0)
        if unread:
            reasons["not checked: label not readable"] += unread
        report = {
            "rows": int(N) + unread,
            "checked": int(checked.sum()),
            "not_checked": int((~checked).sum()) + unread,
            "not_checked_reasons": dict(reasons.most_common(10)),
            "suspects": int(suspect.sum()),
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
                "checked": int(lm_ok.sum()),
                "angle_deg": _stats(lm_angle[lm_ok]),
                "residual": _stats(self.rows["landmark_residual"][lm_ok]),
                "not_checked_reasons": lm_reasons,
            },
            **out,
        }
        if "views" not in report:
            report["views"] = {"checked": 0, "reason": self.view_reason}
        if "time" not in report:
            report["time"] = {"checked": 0, "reason": "no frame column"}
        return report

    def parts_keys(self):
        keys = ["line", "finite", "abs_yaw", "lm_angle", "lm_res", "lm_reason"]
        if self.has_frame:
            keys += ["A", "frame"] + self.track_cols
        return keys

    def _why(self, i, lm_angle, lm_ratio, view_angle, jump) -> str:
        parts = []
        if lm_ratio[i] > self.s.suspect_score:
            parts.append(f"landmarks {lm_angle[i]:.1f} deg from the label")
        if view_angle[i] / mc.VIEW_EXPECTED > self.s.suspect_score:
            parts.append(f"views: {view_angle[i]:.1f} deg from the consensus of its views")
        if jump[i] * self.s.suspect_score / self.s.max_jump_deg > self.s.suspect_score:
            parts.append(f"time: jumps {jump[i]:.1f} deg per frame away from its neighbours and back")
        return "; ".join(parts)

    def _views(self, P, view_reason, finite):
        N = len(P["line"])
        angle = np.full(N, np.nan)
        if self.view_reason:
            return angle, view_reason, {"checked": 0, "reason": self.view_reason}
        cam_names = {v: k for k, v in self.code_tables["camera"].items()}
        seq_names = {v: k for k, v in self.code_tables["sequence"].items()}
        cam_R = np.full((N, 3, 3), np.nan)
        cams = P["camera"]
        seqs = P.get("sequence")
        for code in np.unique(cams):
            sel = cams == code
            name = cam_names.get(int(code))
            if None in self.cams:
                cam = self.cams[None].get(name)
                if cam is not None:
                    cam_R[sel] = cam[0]
            else:
                for sc in np.unique(seqs[sel]):
                    cam = self.cams.get(seq_names.get(int(sc)), {}).get(name)
                    if cam is not None:
                        cam_R[sel & (seqs == sc)] = cam[0]
        have_cam = np.isfinite(cam_R).all((1, 2))
        view_reason[:] = ""
        view_reason[~have_cam] = "camera not in the calibration"
        view_reason[~finite] = "label not finite"
        usable = have_cam & finite
        keys = [P[c] for c in self.view_cols] + [P["frame"]]
        idx = np.flatnonzero(usable)
        order = idx[np.lexsort([k[idx] for k in reversed(keys)])]
        kmat = np.stack([k[order] for k in keys], 1)
        starts = mc.group_starts(kmat)
        sizes = np.diff(np.append(starts, len(order)))
        big = np.repeat(sizes >= MIN_VIEWS, sizes)
        view_reason[order[~big]] = f"fewer than {MIN_VIEWS} views of this head at this frame"
        order = order[big]
        starts = mc.group_starts(kmat[big])
        res = mc.view_consensus(P["A"][order], cam_R[order], starts)
        angle[order] = res["angle"]
        cams_out, named = [], []
        if len(order):
            off = mc.camera_offsets(res["offset"], cams[order])
            for k in np.argsort(-off["angle"]):
                entry = {
                    "camera": cam_names.get(int(off["codes"][k])),
                    "rows": int(off["n"][k]),
                    "offset_deg": round(float(off["angle"][k]), 4),
                    "rotvec_deg": [round(float(v), 4) for v in off["median"][k]],
                    "significant": bool(off["significant"][k]),
                }
                cams_out.append(entry)
                if entry["significant"]:
                    named.append(entry["camera"])
        ok = np.isfinite(angle)
        summary = {
            "calibration": self.calibration_files,
            "checked": int(ok.sum()),
            "groups": int(len(starts)),
            "min_views": MIN_VIEWS,
            "angle_deg": _stats(angle[ok]),
            "cameras_with_offset": named,
            "cameras": cams_out,
        }
        return angle, view_reason, summary

    def _time(self, P, finite):
        N = len(P["line"])
        reason = np.full(N, "", dtype=object)
        keys = [P[c] for c in self.track_cols] + [P["frame"]]
        idx = np.flatnonzero(finite)
        order = idx[np.lexsort([k[idx] for k in reversed(keys)])]
        tracks = np.stack([k[order] for k in keys[:-1]], 1) if self.track_cols else np.zeros((len(order), 1))
        starts = mc.group_starts(tracks)
        res = mc.temporal_jumps(P["A"][order], P["frame"][order], starts, self.s.max_gap)
        rate = np.full(N, np.nan)
        rate[order] = res["rate"]
        reason[~np.isfinite(rate)] = f"no neighbour on both sides within {self.s.max_gap} frames"
        reason[~finite] = "label not finite"
        ok = np.isfinite(rate)
        flagged = ok & (rate > self.s.max_jump_deg)
        summary = {
            "tracks": [*self.track_cols] or ["(whole table)"],
            "checked": int(ok.sum()),
            "jumps": int(flagged.sum()),
            "rate_deg_per_frame": _stats(rate[ok]),
        }
        return rate, reason, summary

    # ------------------------------------------------------------------ outputs
    def columns(self, offset: int, n: int) -> dict:
        """The output columns of rows ``offset .. offset + n`` (in input order)."""
        out = {c: self.rows[c][offset : offset + n] for c in COLUMNS if c != "consistency_note"}
        out["consistency_note"] = self.rows["consistency_note"].slice(offset, n)
        return {c: out[c] for c in COLUMNS}

    def worst_order(self) -> np.ndarray:
        """Row indices of the suspects, highest score first."""
        s = self.rows["consistency_score"]
        sus = np.flatnonzero(self.rows["suspect"])
        return sus[np.argsort(-s[sus], kind="stable")]

    def describe_rows(self, batches, idx, key_cols) -> list:
        """``{row, key columns..., score, reason}`` of the rows ``idx`` (global indices), read from ``batches``."""
        want = {int(i): k for k, i in enumerate(idx)}
        out = [None] * len(idx)
        offset = 0
        for batch in batches:
            n = batch.num_rows
            hit = [i for i in want if offset <= i < offset + n]
            if hit:
                sub = batch.select(key_cols).take(np.array([i - offset for i in hit])).to_pylist()
                for i, rec in zip(hit, sub):
                    out[want[i]] = {
                        "row": int(self.rows["line"][i]),
                        **rec,
                        "score": round(float(self.rows["consistency_score"][i]), 3),
                        "landmark_angle": _r(self.rows["landmark_angle"][i]),
                        "view_angle": _r(self.rows["view_angle"][i]),
                        "jump_rate": _r(self.rows["jump_rate"][i]),
                        "reason": self.rows["consistency_note"][i],
                    }
            offset += n
        return out


def canonical_labels(system, cols, eff, res) -> np.ndarray:
    """The audited labels as canonical matrices ``(n, 3, 3)``; NaN for rows that are not finite rotations."""
    values = np.stack(cols, axis=-1)
    bad = res["non_finite"] | res.get("not_rotation", False)
    values = np.where(np.asarray(bad)[:, None], 0.0, values)
    A = system.to_canonical(system.from_angles(values) if eff == "angles" else values.reshape(-1, 3, 3))
    A[np.asarray(bad)] = np.nan
    return A


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
    report["worst"] = cons.describe_rows(reread(), top, key_cols)
    if suspects:
        from ..io import write_table

        rows = report["worst"] if len(order) <= len(top) else cons.describe_rows(reread(), order, key_cols)
        write_table(suspects_table(rows, key_cols), suspects, overwrite=overwrite)
        report["suspects_file"] = str(suspects)
    if plots:
        from .draw_consistency import FOLDER, consistency_page

        pics = consistency_page(cons, report, reread(), top[: cons.s.drawn], plots, images, overwrite)
        report["page"] = f"{plots}/{FOLDER}/index.html"
        report["not_drawn"] = [f"{w}: {r}" for w, r in pics["missing"]]
    return report
