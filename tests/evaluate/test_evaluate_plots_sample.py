"""``--plots`` says when it is drawn from a sample (every k-th pair past 400,000 pairs) and uses every kept row."""

from types import SimpleNamespace

import numpy as np

from hpe_cli.pipelines.evaluate.outputs import Sample
from hpe_cli.report.eval_plots import _drawn


def _rows(n, start):
    yaw = np.arange(start, start + n, dtype=np.float64)
    return SimpleNamespace(
        n=n,
        gt_angles=np.column_stack([yaw * 0, yaw, yaw * 0]),
        geodesic=yaw,
        mae_wrapped=np.column_stack([yaw, yaw, yaw]),
    )


def test_sample_keeps_every_kth_pair_and_says_so():
    s = Sample(cap=100)
    for a in range(0, 1000, 37):
        s.add(_rows(min(37, 1000 - a), a))
    r = s.rows()
    assert r.step == 16 and r.n <= 100
    assert _drawn(r) == f"sample: every 16-th pair, {r.n} pairs"
    # the kept rows are spread over the whole run (first and last sixteenth both present)
    assert r.geodesic.min() < 1000 / 16 and r.geodesic.max() > 1000 - 1000 / 16
    small = Sample(cap=100)
    small.add(_rows(50, 0))
    assert _drawn(small.rows()) == "50 pairs"
