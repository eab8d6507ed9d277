"""Matrix validation reports bad input and never "fixes" it."""

import numpy as np
import pytest

from hpe_cli.rotation import check_rotation, rotation_mask, rotation_reasons


def test_reasons():
    R = np.stack([np.eye(3), np.diag([1.0, 1, -1]), np.eye(3) * 1.01, np.full((3, 3), np.nan), np.eye(3) + 1e-7])
    assert rotation_mask(R).tolist() == [True, False, False, False, True]
    reasons = rotation_reasons(R)
    assert "reflection" in reasons[1] and "orthonormal" in reasons[2] and "non-finite" in reasons[3]
    before = R.copy()
    with pytest.raises(ValueError, match="row 1"):
        check_rotation(R)
    assert np.array_equal(before, R, equal_nan=True)
