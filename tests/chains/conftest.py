"""Shared inputs and oracles of the chain tests: the golden AFLW2000 predictions and their ``hpe evaluate``
errors, the Panoptic pizza1 sample, 300W-LP's matrix and the geodesic distance from SciPy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REALDATA, hpe

GOLDEN = Path(__file__).resolve().parents[3] / "shared" / "golden" / "evaluate" / "aflw16m"
PIZZA = REALDATA / "panoptic_160906_pizza1"
#: the BGR colours ``hpe draw`` gives the x, y, z axes
COLOURS = ((0, 0, 255), (0, 255, 0), (255, 0, 0))


def a300wlp(p, y, r):
    """300W-LP's A = Rx(p)^T Ry(y)^T Rz(r)^T = (Rz(r) Ry(y) Rx(p))^T of degrees, from SciPy."""
    return Rotation.from_euler("ZYX", [r, y, p], degrees=True).as_matrix().T


def geodesic_deg(R1, R2) -> float:
    """The angle of ``R1^T R2`` in degrees (SciPy's rotation vector norm: exact near 0, unlike ``arccos`` of the
    trace); one pair of (3, 3) matrices."""
    return float(np.degrees(Rotation.from_matrix(np.asarray(R1).T @ np.asarray(R2)).magnitude()))


@pytest.fixture
def errors(realdata, tmp_path):
    """``hpe evaluate`` of the golden AFLW2000 predictions: the per-row errors table (Parquet)."""
    if not GOLDEN.exists():
        pytest.skip("golden predictions not available")
    out = tmp_path / "errors.parquet"
    args = ("--pred-system", "300w_lp", "--gt-system", "300w_lp", "-o", out)
    hpe("evaluate", GOLDEN / "pred.csv", GOLDEN / "gt.csv", *args, ok=True)
    return out
