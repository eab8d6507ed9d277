"""Column names of a label table's rotation and the columns of a :class:`~hpe_cli.rotation.Conversion`.

Pure numpy: the dataset readers build their tables with these, and :mod:`hpe_cli.io.layout` re-exports them
with the rest of the table layout.
"""

from __future__ import annotations

import numpy as np

ANGLE_COLS = ["pitch", "yaw", "roll"]
ANGLE2_COLS = ["pitch_2", "yaw_2", "roll_2"]
MATRIX_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]
LABEL_COLS = ANGLE_COLS + ANGLE2_COLS + MATRIX_COLS + ["gimbal_lock", "roundtrip_err"]


def conversion_columns(conv) -> dict:
    """Output columns (name -> 1-D array) of a :class:`~hpe_cli.rotation.Conversion`."""
    out = {}
    for n, c in enumerate(ANGLE_COLS):
        out[c] = conv.primary[:, n]
    for n, c in enumerate(ANGLE2_COLS):
        out[c] = conv.secondary[:, n]
    flat = conv.matrix.reshape(-1, 9)
    for n, c in enumerate(MATRIX_COLS):
        out[c] = flat[:, n]
    out["gimbal_lock"] = np.asarray(conv.gimbal_lock, dtype=bool)
    out["roundtrip_err"] = conv.roundtrip_err
    return out
