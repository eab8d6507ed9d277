"""Summaries of any number of pairs in flat memory: streamed sums, exact percentiles from a float32 spill.

:class:`Accumulator` takes the per-row results of one chunk of pairs at a
time (:class:`hpe_cli.metrics.evaluate.PairRows`) and keeps only sums and
counts per group (all rows, each ``--by`` value, each yaw bin) plus the
geodesic errors as float32 in a temporary file (4 bytes per pair, plus 4 per
grouping). :meth:`Accumulator.report` turns them into the same report blocks
as :func:`hpe_cli.metrics.evaluate.summary`; medians and percentiles are
exact over the spilled float32 errors (float32 rounding: < 1e-6 relative).
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from .protocols import PROTOCOLS
from .rotation_errors import AXES
from .select import percentiles_of_pieces, top_counts

ANGLES = ("pitch", "yaw", "roll")
WITHIN = (5, 10, 15, 30)
#: the percentiles of the geodesic error in the report (median, p90, p95)
QUANTILES = (50, 90, 95)
#: values of a spill read back at once
SPILL_PIECE = 1 << 20


def _items(rows):
    """``(path, mask or None, values or None)`` of every summed quantity of one chunk (None values: a count)."""
    g = rows.geodesic
    yield ("n",), None, None
    yield ("geo",), None, g
    for t in WITHIN:
        yield ("within", t), g <= t, None
    for k, a in enumerate(AXES):
        yield ("maev", a), None, rows.maev[:, k]
    yield ("frobenius",), None, rows.frobenius
    for blk in ("mae_wrapped", "mae_best_of_two"):
        e = getattr(rows, blk)
        for k, a in enumerate(ANGLES):
            yield (blk, a), None, e[:, k]
    for name, pr in rows.protocols.items():
        yield from _protocol_items(name, pr)


def _protocol_items(name, pr):
    """The :func:`_items` of one protocol's rows (``ProtocolRows``)."""
    keep = pr.keep
    yield ("p", name, "n"), keep, None
    yield ("p", name, "dropped"), ~keep, None
    for k, lab in enumerate(pr.angle_labels):
        yield ("p", name, "err", lab), keep, pr.err[:, k]
    for s, m in pr.splits.items():
        yield ("p", name, "split", s, "n"), keep & m, None
        for k, lab in enumerate(pr.angle_labels):
            yield ("p", name, "split", s, lab), keep & m, pr.err[:, k]
    for s, v in pr.scalars.items():
        yield ("p", name, "scalar", s), keep, v
    for s, (labels, v) in pr.vectors.items():
        for j, lab in enumerate(labels):
            yield ("p", name, "vector", s, lab), keep, v[:, j]
    for s, m in pr.counts.items():
        yield ("p", name, "count", s), keep & m, None
    for side, m in pr.reexpressed.items():
        if m is not None:
            yield ("p", name, "rx", side), m, None


class _Grouping:
    """Sums and counts per group of one grouping (all rows, --by values or yaw bins)."""

    def __init__(self, n_groups: int = 0):
        self.n = n_groups
        self.sums: dict = {}
        self.counts: dict = {}
        self.max = np.full(n_groups, -np.inf)
        self.static: dict = {}

    def grow(self, n: int):
        if n <= self.n:
            return
        pad = n - self.n
        for d in (self.sums, self.counts):
            for k, v in d.items():
                d[k] = np.concatenate([v, np.zeros(pad)])
        self.max = np.concatenate([self.max, np.full(pad, -np.inf)])
        self.n = n

    def add(self, rows, codes):
        self.merge(self.partial(rows, codes))

    def partial(self, rows, codes) -> tuple:
        """The sums and counts of one chunk (no state read or written: any thread may compute it)."""
        return self.partial_of(_items(rows), rows.protocols, len(rows.geodesic), codes, rows.geodesic)

    def partial_of(self, items, protocols: dict, n: int, codes, geodesic=None) -> tuple:
        """:meth:`partial` of ``items`` (:func:`_items`) of ``n`` rows, ``protocols`` (name -> ``ProtocolRows``)
        their protocols, ``geodesic`` their errors (for the maximum; None: no maximum)."""
        G = self.n
        single = codes is None  # one group (all rows): plain sums, no bincount
        counts, sums = {}, {}
        seen: dict = {}  # id(mask) -> (mask, its count); holding the mask keeps its id from being reused
        for path, mask, values in items:
            k = n
            if mask is not None:
                if id(mask) not in seen:
                    seen[id(mask)] = (mask, int(np.count_nonzero(mask)))
                k = seen[id(mask)][1]
                if k == n:  # a mask that keeps every row is not applied (no copy, the same sums)
                    mask = None
            if single:
                counts[path] = np.array([float(k)])
            else:
                c = codes if mask is None else codes[mask]
                counts[path] = np.bincount(c, minlength=G).astype(np.float64)
            if values is not None:
                v = values if mask is None else values[mask]
                if single:
                    sums[path] = np.array([float(np.sum(v))])
                else:
                    sums[path] = np.bincount(c, weights=v, minlength=G) if len(c) else np.zeros(G)
        static = {
            ("p", name, "rx", side): "from matrix"
            for name, pr in protocols.items()
            for side, m in pr.reexpressed.items()
            if m is None
        }
        mx = np.full(1 if single else G, -np.inf)
        if geodesic is not None and len(geodesic):
            if single:
                mx[0] = float(geodesic.max())
            else:
                np.maximum.at(mx, codes, geodesic)
        return counts, sums, static, mx

    def merge(self, part) -> None:
        """Add a :meth:`partial` (in chunk order: the sums are then the same as one thread's)."""
        counts, sums, static, mx = part
        G = self.n
        for path, cnt in counts.items():
            self.counts[path] = self.counts.get(path, np.zeros(G)) + cnt
        for path, v in sums.items():
            self.sums[path] = self.sums.get(path, np.zeros(G)) + v
        self.static.update(static)
        self.max = np.maximum(self.max, mx)

    def mean(self, path, g):
        c = self.counts.get(path)
        if c is None or not c[g]:
            return None
        v = self.sums[path][g] / c[g]
        return None if np.isnan(v) else float(v)

    def count(self, path, g) -> int:
        c = self.counts.get(path)
        return 0 if c is None else int(c[g])


def _avg(values):
    return float(np.mean(values)) if values and all(v is not None for v in values) else None


class Accumulator:
    """Streamed report of any number of chunks of pairs.

    Parameters
    ----------
    protocols : dict
        name -> :class:`hpe_cli.metrics.protocols.Protocol` (for the static fields).
    yaw_edges : ndarray or None
        Yaw-bin edges (degrees) over the GT system's range.
    by : bool
        Whether chunks come with ``--by`` values.
    spill_dir : str, optional
        Folder for the float32 spill (the system temp folder by default).
    """

    #: threads that read the spill back for the percentiles' second pass (integer counts: the same whatever the
    #: number)
    threads = 1

    def __init__(self, protocols, yaw_edges=None, by=False, spill_dir=None, percentiles=True):
        self.protocols = protocols
        self.edges = yaw_edges
        self.all = _Grouping(1)
        self.by = _Grouping(0) if by else None
        self.by_labels: dict = {}
        self.bins = _Grouping(len(yaw_edges) - 1) if yaw_edges is not None else None
        self.percentiles = percentiles
        self._files = {}
        self._dir = spill_dir
        self.n = 0
        #: :func:`hpe_cli.metrics.select.top_counts` of every spilled error (the percentiles' first pass)
        self.top = np.zeros(1 << 16, dtype=np.int64)

    def _spill(self, name, arr):
        f = self._files.get(name)
        if f is None:
            fd, path = tempfile.mkstemp(prefix=f"hpe_eval_{name}_", suffix=".bin", dir=self._dir)
            f = self._files[name] = (os.fdopen(fd, "wb"), path, arr.dtype)
        np.ascontiguousarray(arr).tofile(f[0])

    def _by_codes(self, values):
        import pandas as pd

        codes, uniques = pd.factorize(pd.Series(values), use_na_sentinel=False)
        mapping = np.empty(len(uniques), dtype=np.int64)
        for k, u in enumerate(uniques):
            key = _plain(u)
            if key not in self.by_labels:
                self.by_labels[key] = len(self.by_labels)
            mapping[k] = self.by_labels[key]
        self.by.grow(len(self.by_labels))
        return mapping[codes]

    def bin_codes(self, gt_yaw):
        return np.clip(np.searchsorted(self.edges, gt_yaw, side="right") - 1, 0, len(self.edges) - 2)

    def partial(self, rows) -> dict:
        """What :meth:`add` needs of a chunk that does not depend on earlier chunks (any thread may compute it)."""
        out = {"all": self.all.partial(rows, None), "geo": rows.geodesic.astype(np.float32)}
        if self.percentiles:  # the first pass of the exact percentiles, on the thread that scored the chunk
            top = top_counts(out["geo"])
            nz = np.flatnonzero(top)  # a few hundred of the 65,536 counts: kept sparse while the chunk waits
            out["top"] = (nz, top[nz])
        if self.bins is not None:
            c = self.bin_codes(rows.gt_angles[:, 1])
            out["bins"], out["bin_codes"] = self.bins.partial(rows, c), c.astype(np.int32)
        return out

    def add(self, rows, by_values=None, partial=None) -> dict:
        """Add one chunk of per-row results (``PairRows``) and its ``--by`` values (``partial``: :meth:`partial`
        of the same rows, computed ahead on another thread). Returns the chunk's group codes (``by``, ``bins``:
        int arrays, or None), what :meth:`protocol_partial` takes for a protocol of the same rows scored later."""
        part = self.partial(rows) if partial is None else partial
        n = rows.n
        self.n += n
        self.all.merge(part["all"])
        if self.percentiles:
            self._spill("geo", part["geo"])
            nz, counts = part["top"]
            self.top[nz] += counts
        c = None
        if self.by is not None:
            c = self._by_codes(by_values)
            self.by.add(rows, c)
            if self.percentiles:
                self._spill("by", c.astype(np.int32))
        if self.bins is not None:
            self.bins.merge(part["bins"])
            if self.percentiles:
                self._spill("bin", part["bin_codes"])
        return {"by": c, "bins": None if self.bins is None else part["bin_codes"]}

    def protocol_partial(self, name: str, pr, codes: dict) -> dict:
        """The sums of one protocol's rows (``ProtocolRows``) of a chunk already added, scored after the others
        (opal23-align, once its mean is known); ``codes`` is what :meth:`add` returned for that chunk. Any
        thread may compute it; :meth:`merge_protocol` adds it, in chunk order."""
        n, protocols = len(pr.keep), {name: pr}
        out = {"all": self.all.partial_of(_protocol_items(name, pr), protocols, n, None)}
        if self.by is not None:
            out["by"] = self.by.partial_of(_protocol_items(name, pr), protocols, n, codes["by"])
        if self.bins is not None:
            out["bins"] = self.bins.partial_of(_protocol_items(name, pr), protocols, n, codes["bins"])
        return out

    def merge_protocol(self, part: dict) -> None:
        """Add a :meth:`protocol_partial` (in chunk order, as :meth:`add` adds the chunks)."""
        for key, grouping in (("all", self.all), ("by", self.by), ("bins", self.bins)):
            if key in part:
                grouping.merge(part[key])

    # ------------------------------------------------------------------ report
    def _load(self, name):
        f = self._files.get(name)
        if f is None:
            return None
        f[0].flush()
        size = os.path.getsize(f[1])
        if not size:
            return np.zeros(0, dtype=f[2])
        return np.memmap(f[1], dtype=f[2], mode="r")

    def _pieces(self, name, rows: int = SPILL_PIECE, start: int = 0, stop: int | None = None):
        """The spill ``name`` read back ``rows`` values at a time (no memory map: its pages would count in the
        process's peak), from value ``start`` to ``stop`` (None: the end)."""
        _, path, dtype = self._files[name]
        size = np.dtype(dtype).itemsize
        with open(path, "rb") as f:
            f.seek(start * size)
            left = -1 if stop is None else stop - start
            while left:
                v = np.fromfile(f, dtype=dtype, count=rows if left < 0 else min(rows, left))
                if not len(v):
                    return
                left -= len(v) if left > 0 else 0
                yield v

    def _parts(self, name, n: int) -> list:
        """The spill ``name`` of ``n`` values as :attr:`threads` readers of consecutive parts (callables)."""
        k = max(1, min(self.threads, n // SPILL_PIECE))
        cuts = [n * j // k for j in range(k + 1)]
        return [lambda a=a, b=b: self._pieces(name, start=a, stop=b) for a, b in zip(cuts[:-1], cuts[1:])]

    def _quantiles(self, codes, n_groups):
        """``{group: (median, p90, p95)}`` exact over the spilled float32 errors."""
        geo = self._load("geo")
        out = {}
        if geo is None or not len(geo):
            return out
        if codes is None:  # read piece by piece (flat memory), np.percentile's numbers to the bit
            parts = self._parts("geo", len(geo))
            q = percentiles_of_pieces(parts, len(geo), QUANTILES, top=self.top, threads=self.threads)
            if q is None:
                q = np.percentile(np.asarray(geo, dtype=np.float32), QUANTILES)
            return {0: tuple(float(x) for x in q)}
        c = np.asarray(codes)
        order = np.argsort(c, kind="stable")
        bounds = np.searchsorted(c[order], np.arange(n_groups + 1))
        for g in range(n_groups):
            sel = order[bounds[g] : bounds[g + 1]]
            if len(sel):
                q = np.percentile(np.asarray(geo[np.sort(sel)], dtype=np.float32), QUANTILES)
                out[g] = tuple(float(x) for x in q)
        return out

    def _block(self, G: _Grouping, g: int, quant) -> dict:
        n = G.count(("n",), g)
        geo = {"mean": G.mean(("geo",), g)}
        med = quant.get(g) if quant else None
        geo.update(
            {
                "median": med[0] if med else None,
                "p90": med[1] if med else None,
                "p95": med[2] if med else None,
                "max": float(G.max[g]) if n else None,
            }
        )
        geo.update({f"within_{t}": (G.count(("within", t), g) / n if n else None) for t in WITHIN})
        maev = {a: G.mean(("maev", a), g) for a in AXES}
        maev["mean"] = _avg(list(maev.values()))
        metrics = {"geodesic": geo, "maev": maev, "frobenius": {"mean": G.mean(("frobenius",), g)}}
        for blk in ("mae_wrapped", "mae_best_of_two"):
            e = {a: G.mean((blk, a), g) for a in ANGLES}
            e["mean"] = _avg(list(e.values())) if n else None
            metrics[blk] = e
        return {"n": n, "metrics": metrics, "protocols": {name: self._protocol(G, g, name) for name in self.protocols}}

    def _protocol(self, G: _Grouping, g: int, name: str) -> dict:

        p = PROTOCOLS[name]
        labels = ("pitch", "yaw", "roll")
        for path in G.sums:
            if path[:3] == ("p", name, "err"):
                labels = tuple(q[3] for q in G.sums if q[:3] == ("p", name, "err"))
                break
        out = {"n": G.count(("p", name, "n"), g)}
        means = [G.mean(("p", name, "err", lab), g) for lab in labels]
        out.update(dict(zip(labels, means)))
        out["mean"] = _avg(means)
        out["dropped"] = G.count(("p", name, "dropped"), g)
        splits = dict.fromkeys(q[3] for q in G.counts if q[:3] == ("p", name, "split"))
        for s in splits:
            sm = [G.mean(("p", name, "split", s, lab), g) for lab in labels]
            out[s] = {"n": G.count(("p", name, "split", s, "n"), g), **dict(zip(labels, sm)), "mean": _avg(sm)}
        for q in G.sums:
            if q[:3] == ("p", name, "scalar"):
                out[q[3]] = G.mean(q, g)
        vectors: dict = {}
        for q in G.sums:
            if q[:3] == ("p", name, "vector"):
                vectors.setdefault(q[3], {})[q[4]] = G.mean(q, g)
        for k, d in vectors.items():
            d["mean"] = _avg(list(d.values()))
            out[k] = d
        for q in G.counts:
            if q[:3] == ("p", name, "count"):
                out[q[3]] = G.count(q, g)
        rx = {q[3]: G.count(q, g) for q in G.counts if q[:3] == ("p", name, "rx")}
        rx.update({q[3]: v for q, v in G.static.items() if q[:3] == ("p", name, "rx")})
        if rx:
            out["re_expressed"] = {s: rx[s] for s in ("pred", "gt") if s in rx}
        if out["mean"] is None and "frobenius" in out:
            out["mean"] = out["frobenius"]
        out.update({"system": p.system, "source": p.source, "units": p.units})
        if p.notes:
            out["notes"] = list(p.notes)
        return out

    def report(self) -> dict:
        """``{"n", "metrics", "protocols"}`` plus ``by_groups`` / ``yaw_bins`` lists when asked."""
        out = self._block(self.all, 0, self._quantiles(None, 1) if self.percentiles else None)
        if self.by is not None:
            labels = sorted(self.by_labels, key=_sort_key)
            q = self._quantiles(self._load("by"), self.by.n) if self.percentiles else {}
            out["by_groups"] = {str(lab): self._block(self.by, self.by_labels[lab], q) for lab in labels}
        if self.bins is not None:
            q = self._quantiles(self._load("bin"), self.bins.n) if self.percentiles else {}
            out["yaw_bins"] = [
                {"lo": float(self.edges[k]), "hi": float(self.edges[k + 1]), **self._block(self.bins, k, q)}
                for k in range(self.bins.n)
            ]
        return out

    def close(self):
        for f, path, _ in self._files.values():
            try:
                f.close()
            finally:
                if os.path.exists(path):
                    os.unlink(path)
        self._files = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _plain(u):
    if isinstance(u, np.generic):
        u = u.item()
    if isinstance(u, float) and np.isnan(u):
        return "NaN"
    return u if isinstance(u, (str, int, float, bool)) or u is None else str(u)


def _sort_key(x):
    return (0, x, "") if isinstance(x, (int, float)) and not isinstance(x, bool) else (1, 0, str(x))
