from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

settings.register_profile("hpe", max_examples=60, deadline=None)
settings.load_profile("hpe")

REALDATA = Path(__file__).resolve().parents[2] / "shared" / "realdata"
ROOT = Path(__file__).resolve().parents[1]


def sample_data_script():
    """``scripts/make_sample_data.py`` as a module (synthetic Panoptic sequences, tars, videos, templates)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_sample_data", ROOT / "scripts" / "make_sample_data.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture
def realdata():
    if not REALDATA.exists():
        pytest.skip("../shared/realdata is not available")
    return REALDATA


def canonical_A(pyr_deg):
    """SPEC §2's expanded 300W-LP matrix, written out independently of the package."""
    p, y, r = np.deg2rad(np.asarray(pyr_deg, dtype=float)).T
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    return np.stack(
        [
            np.stack([cy * cr, cy * sr, -sy], -1),
            np.stack([-cp * sr + sp * sy * cr, cp * cr + sp * sy * sr, sp * cy], -1),
            np.stack([sp * sr + cp * sy * cr, -sp * cr + cp * sy * sr, cp * cy], -1),
        ],
        -2,
    )
