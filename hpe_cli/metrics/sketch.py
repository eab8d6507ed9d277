"""Quantiles of a stream in bounded memory: exact up to a number of values, a fixed-resolution histogram beyond.

:class:`StreamQuantiles` keeps the values it is given until there are more
than ``exact_cap`` of them (the default, 2^20 values, is 8 MiB of float64); it
then bins them, and everything after, into a histogram of ``resolution``-wide
bins over ``[0, hi]`` (values above ``hi`` go to the last bin; the maximum is
kept exactly). Quantiles are then the centre of the bin holding the rank: within
``resolution / 2`` of numpy's linear-interpolation percentile of the same
values, plus the interpolation itself (at most the gap between two neighbouring
values).

:class:`BinnedMedians` does the same per group (a few |yaw| bins), for the
medians :func:`hpe_cli.metrics.consistency.fit_expected_landmark_angle` fits.
"""

from __future__ import annotations

import numpy as np

#: values kept exactly before a stream switches to its histogram
EXACT_CAP = 1 << 20


class StreamQuantiles:
    """Percentiles of values given chunk by chunk.

    Parameters
    ----------
    hi : float
        Top of the histogram range (values are expected in ``[lo, hi]``; outside, they count in the end bins).
    resolution : float
        Width of a histogram bin, in the values' unit.
    exact_cap : int
        Values kept exactly before switching to the histogram.
    lo : float
        Bottom of the histogram range (default 0).
    """

    def __init__(self, hi: float, resolution: float, exact_cap: int = EXACT_CAP, lo: float = 0.0):
        self.lo, self.hi, self.resolution, self.cap = float(lo), float(hi), float(resolution), int(exact_cap)
        self.nbins = int(np.ceil((self.hi - self.lo) / self.resolution)) + 1
        self.parts = []
        self.hist = None
        self.n = 0
        self.max = -np.inf
        self.min = np.inf

    @property
    def exact(self) -> bool:
        """True while every value is kept."""
        return self.hist is None

    def add(self, values) -> None:
        """Add the finite entries of ``values`` (NaN and inf are ignored)."""
        x = np.asarray(values)
        x = x[np.isfinite(x)]
        if not x.size:
            return
        self.n += x.size
        self.max = max(self.max, float(x.max()))
        self.min = min(self.min, float(x.min()))
        if self.hist is None:
            self.parts.append(x.copy())
            if self.n > self.cap:
                self.hist = np.zeros(self.nbins, dtype=np.int64)
                for p in self.parts:
                    self._bin(p)
                self.parts = []
        else:
            self._bin(x)

    def _bin(self, x) -> None:
        k = np.floor((np.asarray(x, np.float64) - self.lo) / self.resolution)
        k = np.clip(k, 0, self.nbins - 1).astype(np.int64)
        self.hist += np.bincount(k, minlength=self.nbins)

    def percentile(self, q) -> np.ndarray:
        """Percentiles ``q`` (0-100) of the values given; NaN when there are none."""
        q = np.atleast_1d(np.asarray(q, dtype=np.float64))
        if self.n == 0:
            return np.full(q.shape, np.nan)
        if self.hist is None:
            return np.percentile(np.concatenate(self.parts).astype(np.float64), q)
        return np.maximum(_hist_percentile(self.hist, self.n, q, self.resolution, self.max, self.lo), self.min)

    def mad(self, centre: float) -> float:
        """Median of ``|x - centre|`` over the values given (NaN when none); from the bin centres once binned."""
        if self.n == 0:
            return float("nan")
        if self.hist is None:
            return float(np.median(np.abs(np.concatenate(self.parts).astype(np.float64) - centre)))
        nz = np.flatnonzero(self.hist)
        dev = np.abs(self.lo + (nz + 0.5) * self.resolution - centre)
        order = np.argsort(dev, kind="stable")
        c = np.cumsum(self.hist[nz][order])
        return float(dev[order][np.searchsorted(c, (self.n - 1) // 2, side="right")])

    def stats(self) -> dict:
        """``{n, median, p90, p99, max}`` (rounded to 3 decimals); ``resolution`` too once binned."""
        if self.n == 0:
            return {"n": 0}
        q = self.percentile([50, 90, 99])
        r = lambda v: round(float(v), 3)  # noqa: E731
        out = {"n": int(self.n), "median": r(q[0]), "p90": r(q[1]), "p99": r(q[2]), "max": r(self.max)}
        if self.hist is not None:
            out["resolution"] = self.resolution
        return out


def _hist_percentile(hist, n, q, resolution, vmax, lo=0.0) -> np.ndarray:
    c = np.cumsum(hist)
    rank = np.floor(q / 100.0 * (n - 1))  # the 0-based rank below numpy's interpolation point
    k = np.searchsorted(c, rank, side="right")
    return np.minimum(lo + (k + 0.5) * resolution, vmax)


class BinnedMedians:
    """Per-group medians of ``x`` and of ``y`` for a handful of groups, in bounded memory.

    ``x`` (the grouping variable, e.g. |yaw|) and ``y`` (e.g. an angle) are kept
    exactly up to ``exact_cap`` pairs, then binned at ``x_resolution`` and
    ``y_resolution`` per group (a histogram of ``x`` over ``[0, x_hi]`` and of
    ``y`` over ``[0, y_hi]`` for each group).
    """

    def __init__(self, edges, x_hi, y_hi, x_resolution, y_resolution, exact_cap: int = EXACT_CAP):
        self.edges = np.asarray(edges, dtype=np.float64)
        G = len(self.edges) - 1
        self.x = [StreamQuantiles(x_hi, x_resolution, exact_cap) for _ in range(G)]
        self.y = [StreamQuantiles(y_hi, y_resolution, exact_cap) for _ in range(G)]
        self.pairs_x, self.pairs_y, self.n, self.cap = [], [], 0, int(exact_cap)

    def add(self, x, y) -> None:
        """Add the pairs where both are finite."""
        x = np.asarray(x)
        y = np.asarray(y)
        ok = np.isfinite(x) & np.isfinite(y)
        if not ok.any():
            return
        x, y = x[ok], y[ok]
        self.n += x.size
        if self.pairs_x is not None:
            self.pairs_x.append(x.copy())
            self.pairs_y.append(y.copy())
            if self.n <= self.cap:
                return
            x, y = np.concatenate(self.pairs_x), np.concatenate(self.pairs_y)
            self.pairs_x = self.pairs_y = None
        g = self.group(x)
        for k in np.unique(g):  # a handful of groups, not rows
            sel = g == k
            self.x[k].add(x[sel])
            self.y[k].add(y[sel])

    def group(self, x) -> np.ndarray:
        return np.clip(np.searchsorted(self.edges, np.asarray(x, np.float64), side="right") - 1, 0, len(self.x) - 1)

    @property
    def exact(self) -> bool:
        return self.pairs_x is not None

    def values(self):
        """The kept pairs ``(x, y)`` while exact (else None)."""
        if self.pairs_x is None:
            return None
        if not self.pairs_x:
            return np.zeros(0, np.float32), np.zeros(0)
        return np.concatenate(self.pairs_x), np.concatenate(self.pairs_y)
