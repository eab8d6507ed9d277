"""Export sampling rules (pure functions over arrays): group splits, ``--split-file``, ``--min-change``,
``--balance``, and which reject reasons are choices (layout rules, sampling) rather than bad input."""

from __future__ import annotations

import hashlib
import re

import numpy as np

from ...errors import HpeError
from .options import SPLIT_NAMES


def parse_split(spec: str):
    """``COL:0.8,0.2`` or ``COL:train=0.8,val=0.2`` -> (column, names, fractions)."""
    try:
        col, rest = spec.split(":", 1)
        items = [s.strip() for s in rest.split(",") if s.strip()]
        names, fr = [], []
        for k, it in enumerate(items):
            if "=" in it:
                n, v = it.split("=", 1)
            else:
                n, v = None, it
            names.append(n)
            fr.append(float(v))
        if not col or not fr or any(f < 0 for f in fr) or sum(fr) <= 0:
            raise ValueError
    except ValueError:
        raise HpeError(f"--split: expected COL:FRACTIONS such as sequence:0.8,0.2, got {spec!r}") from None
    if any(n is None for n in names):
        if len(fr) not in SPLIT_NAMES:
            raise HpeError(f"--split: name the splits (train=0.7,...) when there are more than 3, got {spec!r}")
        names = SPLIT_NAMES[len(fr)]
    check_split_names(names, "--split")
    fr = np.asarray(fr) / sum(fr)
    return ("subject" if col == "identity" else col), list(names), fr


def check_split_names(names, where: str) -> None:
    """Split names become folder and file names: letters, digits, ``_`` and ``-`` only, unique."""
    for n in names:
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_-]*", str(n)):
            raise HpeError(f"{where}: expected split names of letters, digits, '_' and '-', got {n!r}")
    if len(set(names)) != len(names):
        raise HpeError(f"{where}: expected distinct split names, got {', '.join(map(str, names))}")


def group_hash(values, seed: int) -> np.ndarray:
    """A deterministic 64-bit key per group value (sha256 of ``seed:value``)."""
    return np.array(
        [int.from_bytes(hashlib.sha256(f"{seed}:{v}".encode()).digest()[:8], "big") for v in values], dtype=np.uint64
    )


def assign_splits(groups, names, fractions, seed: int = 0) -> np.ndarray:
    """Split rows by group: groups in hash order fill the splits by row count; one group, one split.

    Groups are laid end to end in the order of their hash; a group goes to the split whose share of the rows
    holds the group's midpoint. Deterministic for a given ``seed`` and independent of row order.
    """
    groups = np.asarray(groups).astype(str)
    uniq, inv, counts = np.unique(groups, return_inverse=True, return_counts=True)
    order = np.argsort(group_hash(uniq.tolist(), seed), kind="stable")
    before = np.cumsum(counts[order]) - counts[order]  # rows in earlier groups
    edges = np.cumsum(fractions)[:-1] * groups.size
    which = np.searchsorted(edges, before + counts[order] / 2, side="right")
    split_of_group = np.empty(uniq.size, dtype=object)
    split_of_group[order] = np.asarray(names, dtype=object)[which]
    return split_of_group[inv.reshape(-1)]


def read_split_file(path):
    """``--split-file``: a CSV whose header names the group column, then ``split``; returns (col, mapping)."""
    import pandas as pd

    try:
        t = pd.read_csv(path, dtype=str, keep_default_na=False)
    except Exception as exc:
        raise HpeError(f"{path}: cannot read ({' '.join(str(exc).split())[:160]})") from None
    if t.shape[1] != 2 or "split" not in t.columns:
        raise HpeError(
            f"{path}: expected two columns, a group column (e.g. sequence) and split, got {', '.join(t.columns)}"
        )
    col = [c for c in t.columns if c != "split"][0]
    dup = t[col].duplicated(keep=False) & (t.groupby(col)["split"].transform("nunique") > 1)
    if dup.any():
        k = int(np.flatnonzero(dup.to_numpy())[0])
        raise HpeError(f"{path}: line {k + 2}: group {t[col].iloc[k]!r} is in two splits")
    for n in sorted(set(t["split"].tolist())):
        check_split_names([n], str(path))
    return ("subject" if col == "identity" else col), dict(zip(t[col].tolist(), t["split"].tolist()))


def geodesic(A, B) -> float:
    c = (np.trace(A.T @ B) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def min_change_keep(keys, frames, A, deg: float, ok) -> np.ndarray:
    """Per group (``keys``), in frame order, keep a row only if its rotation differs from the last kept
    one of that group by more than ``deg`` (geodesic angle); the first row of a group is kept.

    Rows with ``ok`` False are skipped (neither kept nor compared). Returns a boolean keep mask.
    """
    n = len(frames)
    keep = np.zeros(n, dtype=bool)
    order = np.lexsort((np.arange(n), frames, keys))
    A = np.asarray(A).reshape(n, 3, 3)
    last = {}
    for i in order.tolist():
        if not ok[i]:
            continue
        k = keys[i]
        prev = last.get(k)
        if prev is None or geodesic(A[prev], A[i]) > deg:
            keep[i] = True
            last[k] = i
    return keep


def parse_balance(spec: str):
    m = re.fullmatch(r"yaw:([0-9.]+):(\d+)", spec or "")
    if not m or float(m.group(1)) <= 0:
        raise HpeError(f"--balance: expected yaw:BIN:MAX (bin width in degrees, max samples per bin), got {spec!r}")
    return float(m.group(1)), int(m.group(2))


def balance_keep(yaw, bin_deg: float, max_per_bin: int, ok, seed: int = 0):
    """At most ``max_per_bin`` usable rows per yaw bin ``[-180 + k*bin, ...)``, chosen with ``seed``.

    Returns (keep mask, bin index per row). Deterministic: bins in order, one generator.
    """
    yaw = np.asarray(yaw, dtype=np.float64)
    bins = np.floor((yaw + 180.0) / bin_deg).astype(np.int64)
    keep = ok.copy()
    rng = np.random.default_rng(seed)
    for b in np.unique(bins[ok]).tolist():
        idx = np.flatnonzero(ok & (bins == b))
        if idx.size > max_per_bin:
            chosen = np.sort(rng.permutation(idx.size)[:max_per_bin])
            drop = np.ones(idx.size, dtype=bool)
            drop[chosen] = False
            keep[idx[drop]] = False
    return keep, bins


CHOICE_PREFIXES = (
    "WHENet rule",
    "DirectMHP normalisation",
    "outside ±99",
    "min-change",
    "balance",
    "image dropped",
    "excluded: ",
    "no 2-D landmarks",
    "Hopenet bins",
    "6DRepNet create_filename_list",
)


def is_choice(reason: str) -> bool:
    """A reject made by a rule the user chose (layout, sampling, split file), not by bad input."""
    return reason.startswith(CHOICE_PREFIXES) or reason.endswith("not listed in --split-file")
