"""A warning when angle columns look like the other unit: degrees that look like radians, and the reverse.

Radians read as degrees give labels that are silently almost frontal. Degrees data where every angle of more
than a handful of rows is within +-pi (3.14 degrees) is implausible, so the run says so on stderr once its outputs
are committed (the check is per run: it needs every row, and rows stream in batches).

Degrees read as radians (``--radians`` on degrees) wrap around many turns and give labels that look random. A head
angle in radians never exceeds 2*pi in magnitude, so a single such value is worth a warning.
"""

from __future__ import annotations

import sys
import threading

import numpy as np

from .transaction import current

#: more rows than this, all within +-pi, are worth a warning
MIN_ROWS = 5
#: an angle read as radians beyond this magnitude is not a head angle in radians (one full turn)
MAX_RADIANS = 2 * np.pi


class UnitsWatch:
    """Running count and largest |value| of the usable angle rows read as degrees in one run."""

    def __init__(self, inputs, unit: str = "degrees"):

        self.inputs, self.unit, self.rows, self.largest = inputs, unit, 0, 0.0
        self._lock = threading.Lock()  # readers may feed it from several threads

    def observe(self, cols, ok=None) -> None:
        if self.unit == "degrees" and self.largest > np.pi:  # the warning can no longer fire: nothing to scan
            return
        cols = [np.asarray(c, dtype=np.float64) for c in cols]
        n = len(cols[0]) if cols and np.ndim(cols[0]) else 0
        if n and (ok is None or bool(np.all(ok))):  # the usual batch: min and max only, no temporaries
            lo, hi = min(float(c.min()) for c in cols), max(float(c.max()) for c in cols)
            if np.isfinite(lo) and np.isfinite(hi):
                self._add(n, max(hi, -lo))
                return
        v = np.stack(cols, axis=-1)
        good = np.isfinite(v).all(axis=-1) if ok is None else (np.asarray(ok) & np.isfinite(v).all(axis=-1))
        if good.any():
            self._add(int(good.sum()), float(np.abs(v[good]).max()))

    def _add(self, rows: int, largest: float) -> None:
        with self._lock:
            self.rows += rows
            self.largest = max(self.largest, largest)

    def message(self) -> str | None:
        where = f"{self.inputs[0]}: " if len(self.inputs) == 1 else ""
        if self.unit == "radians":
            if not self.largest > MAX_RADIANS:
                return None
            return (
                f"Warning: {where}an angle read as radians (--radians) reaches |value| {self.largest:.4g}, more "
                f"than 2*pi (a full turn): if these are degrees, drop --radians"
            )
        if self.rows <= MIN_ROWS or self.largest > np.pi:
            return None
        return (
            f"Warning: {where}every angle read as degrees is within +-pi (largest |value| {self.largest:.3g}, "
            f"more than {MIN_ROWS} rows): if these are radians, add --radians"
        )

    def report(self) -> None:
        msg = self.message()
        if msg is not None:
            print(msg, file=sys.stderr)


def observe_degrees(cols, ok=None) -> None:
    """Feed angle columns read as degrees to the running command's watch (no-op outside a command)."""
    _observe(cols, ok, "degrees")


def observe_radians(cols, ok=None) -> None:
    """Feed angle columns read as radians (``--radians``, before conversion) to the running command's watch."""
    _observe(cols, ok, "radians")


def _observe(cols, ok, unit: str) -> None:

    txn = current()
    if txn is None:
        return
    attr = f"_units_watch_{unit}"
    watch = getattr(txn, attr, None)
    if watch is None:
        watch = UnitsWatch(txn.input_paths(), unit)
        setattr(txn, attr, watch)
        txn.after_commit(watch.report)
    watch.observe(cols, ok)
