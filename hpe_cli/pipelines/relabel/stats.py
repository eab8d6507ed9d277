"""Counts of a Panoptic relabelling run: per unit (plain JSON, so a unit's counts survive in its part) and
for the end-of-run summary (every face and view accounted for)."""

from __future__ import annotations

from collections import Counter

import numpy as np

from .core import summary_tail
from .plan import SKIPPED, Config, Plan


class RmseStats:
    """Fixed-size histogram of fit RMSE values (flat memory) for the summary."""

    EDGES = np.concatenate([np.arange(0.0, 20.0, 0.01), [np.inf]])

    def __init__(self):
        self.counts = np.zeros(len(self.EDGES) - 1, dtype=np.int64)
        self.n = 0
        self.max = -np.inf

    def add(self, values) -> None:
        values = np.asarray(values, dtype=np.float64)
        if values.size:
            self.counts += np.histogram(values, self.EDGES)[0]
            self.n += values.size
            self.max = max(self.max, float(values.max()))

    def merge(self, other: RmseStats) -> None:
        self.counts += other.counts
        self.n += other.n
        self.max = max(self.max, other.max)

    def to_dict(self) -> dict:
        nz = np.flatnonzero(self.counts)
        return {
            "bins": nz.tolist(),
            "counts": self.counts[nz].tolist(),
            "n": self.n,
            "max": self.max if np.isfinite(self.max) else None,
        }

    @classmethod
    def from_dict(cls, d: dict) -> RmseStats:
        out = cls()
        out.counts[np.asarray(d["bins"], dtype=np.intp)] = d["counts"]
        out.n = int(d["n"])
        out.max = -np.inf if d["max"] is None else float(d["max"])
        return out

    def quantile(self, q: float) -> float:
        """Upper edge of the 0.01-wide bin holding quantile ``q`` (capped at the max)."""
        if not self.n:
            return float("nan")
        k = int(np.searchsorted(np.cumsum(self.counts), q * self.n, side="left"))
        return float(min(self.EDGES[min(k + 1, len(self.EDGES) - 2)], self.max))


def unit_stats(res: dict, cfg: Config) -> dict:
    """The summary counts of one :func:`process_chunk` result, as plain JSON."""
    t = res["table"]
    out_of_range = gimbal = 0
    if len(t["frame"]):
        pyr = np.stack([t["pitch"], t["yaw"], t["roll"]], axis=1)
        out_of_range = int((~cfg.system.in_range(pyr)).sum())
        gimbal = int(np.sum(t["gimbal_lock"]))
    rm = RmseStats()
    rm.add(res["fit_rmse"])
    return {
        "frames": res["frames"],
        "faces": res["faces"],
        "views": res["views"],
        "labelled": len(t["frame"]),
        "legacy_considered": res["legacy_considered"],
        "out_of_range": out_of_range,
        "gimbal": gimbal,
        "unreadable": res.get("unreadable", 0),
        "skipped_frames": res.get("skipped_frames", 0),
        "every": res.get("every", 1),
        "view_reasons": dict(Counter(r for r in res["rejects"]["reason"].tolist())),
        "face_reasons": dict(Counter(r for r in res["face_reasons"].tolist() if r)),
        "rmse": rm.to_dict(),
    }


#: the counters of :class:`Stats` that a unit's stats and another run's stats add to
COUNTED = (
    "frames",
    "faces",
    "views",
    "labelled",
    "legacy_considered",
    "out_of_range",
    "gimbal",
    "unreadable",
    "skipped_frames",
)


class Stats:
    """Counts for the end-of-run summary; every face and view is accounted for."""

    def __init__(self):
        self.frames = self.faces = self.views = self.labelled = self.unreadable = self.skipped_frames = 0
        self.legacy_considered = self.out_of_range = self.gimbal = 0
        self.view_reasons: Counter = Counter()
        self.face_reasons: Counter = Counter()
        self.rmse = RmseStats()
        self.every = 1

    def add(self, res: dict, cfg: Config) -> None:
        """Add a :func:`process_chunk` result."""
        self.add_unit(unit_stats(res, cfg))

    def add_unit(self, u: dict) -> None:
        """Add a :func:`unit_stats` dict."""
        for k in COUNTED:
            setattr(self, k, getattr(self, k) + int(u.get(k, 0)))
        self.view_reasons.update(u["view_reasons"])
        self.face_reasons.update(u["face_reasons"])
        self.rmse.merge(RmseStats.from_dict(u["rmse"]))
        self.every = max(self.every, int(u.get("every", 1)))

    def moved(self, reason: str, n: int) -> None:
        """``n`` labelled views were set aside by the writer (``--min-change``)."""
        if n:
            self.labelled -= n
            self.view_reasons[reason] += n

    def merge(self, other: Stats) -> None:
        for k in COUNTED:
            setattr(self, k, getattr(self, k) + getattr(other, k))
        self.view_reasons.update(other.view_reasons)
        self.face_reasons.update(other.face_reasons)
        self.rmse.merge(other.rmse)
        self.every = max(self.every, other.every)

    def summary(
        self, p: Plan | None, cfg: Config, output, rejects_path, n_cameras: int | None = None, title: str | None = None
    ) -> list:
        sysname = getattr(cfg.system, "name", cfg.system)
        if p is not None:
            nums = list(p.frames)
            span = f"{nums[0]}..{nums[-1]}" if nums else "none"
            gaps = f"; {p.missing} frame numbers on that grid have no face file" if p.missing else ""
            head = f"{p.sequence}: {self.frames} frames ({span}{gaps})"
            n_cameras = len(p.cameras)
        else:
            head = f"{title or 'total'}: {self.frames} frames"
        unread = f"; {self.unreadable} unreadable (truncated) face files" if self.unreadable else ""
        if self.skipped_frames:
            unread += f"; {self.skipped_frames} skipped by --every {self.every}"
        lines = [f"{head}{unread}, {self.faces} faces x {n_cameras} cameras = {self.views} views"]
        few = self.face_reasons["too few confident points"]
        broken = self.face_reasons["bad landmarks"]
        skipped = self.face_reasons[SKIPPED]
        fitted = self.faces - few - broken - skipped
        gate = "off" if cfg.max_rmse is None or not np.isfinite(cfg.max_rmse) else f"{cfg.max_rmse:g}"
        lines.append(
            f"faces: {fitted} fitted; {few} with too few confident points; "
            f"{self.face_reasons['bad fit']} bad fits (--max-rmse {gate})"
            + (f"; {broken} with bad landmarks (infinite or absurd)" if broken else "")
            + (f"; {skipped} in frames skipped by --every (not fitted)" if skipped else "")
        )
        if self.rmse.n:
            lines.append(
                f"fit RMSE (cm) of fitted faces: median {self.rmse.quantile(0.5):.2f}, "
                f"p95 {self.rmse.quantile(0.95):.2f}, p99 {self.rmse.quantile(0.99):.2f}, "
                f"max {self.rmse.max:.2f}"
            )
        pct = 100.0 * self.labelled / self.views if self.views else 0.0
        lines.append(f"labelled {self.labelled} of {self.views} views ({pct:.1f}%) in {sysname} -> {output}")
        rej = sum(self.view_reasons.values())
        if rej:
            parts = "; ".join(f"{n} {r}" for r, n in sorted(self.view_reasons.items(), key=lambda x: -x[1]))
            lines.append(f"rejected {rej} views: {parts}" + (f" -> {rejects_path}" if rejects_path else ""))
        lines += summary_tail(
            cfg.legacy,
            self.view_reasons["dropped by legacy rule"],
            self.legacy_considered,
            self.out_of_range,
            self.gimbal,
            sysname,
            "views",
            "WHENet",
        )
        return lines
