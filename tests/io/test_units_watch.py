"""The units warning's verdict from the rows it is fed (``hpe_cli.io.units_watch.UnitsWatch``), with a plain
reading of its rule as the reference: degrees warn when more than MIN_ROWS usable rows all lie within +-pi;
radians warn when one usable value passes 2*pi, naming the largest."""

from __future__ import annotations

import numpy as np
import pytest

from hpe_cli.io.units_watch import MAX_RADIANS, MIN_ROWS, UnitsWatch


def _batches(rng, values):
    """The values as three angle columns cut into batches of random sizes, with a NaN row in each batch."""
    out, a = [], 0
    while a < len(values):
        b = a + int(rng.integers(1, 6))
        v = np.array(values[a:b], dtype=np.float64)
        cols = [np.append(v, np.nan), np.append(v * 0.5, 0.0), np.append(-v, 0.0)]
        out.append(cols)
        a = b
    return out


@pytest.mark.parametrize("seed", range(20))
def test_degrees_verdict_is_the_rule_whatever_the_batches(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 30))
    values = list(rng.uniform(-3.0, 3.0, n))
    if rng.random() < 0.5 and n:
        values[int(rng.integers(0, n))] = float(rng.choice([4.0, -90.0, 179.0]))  # one row past pi: no warning
    w = UnitsWatch(["x.csv"])
    for cols in _batches(rng, values):
        w.observe(cols)
    expected = len(values) > MIN_ROWS and max((abs(v) for v in values), default=0.0) <= np.pi
    assert (w.message() is not None) == expected


def test_radians_message_names_the_largest_value_seen():
    rng = np.random.default_rng(1)
    values = [0.5, 7.0, -1.0, 170.0, 3.0, -12.0]
    w = UnitsWatch(["x.csv"], "radians")
    for cols in _batches(rng, values):
        w.observe(cols)
    assert w.largest == 170.0 > MAX_RADIANS and "reaches |value| 170" in w.message()
