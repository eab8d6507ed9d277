"""The label table layout shared by every command."""
from __future__ import annotations

import numpy as np

ANGLE_COLS = ["pitch", "yaw", "roll"]
ANGLE2_COLS = ["pitch_2", "yaw_2", "roll_2"]
MATRIX_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]
LABEL_COLS = ANGLE_COLS + ANGLE2_COLS + MATRIX_COLS + ["gimbal_lock", "roundtrip_err"]
BBOX_COLS = ["bbox_x", "bbox_y", "bbox_w", "bbox_h"]


def landmark_cols(n: int) -> list:
    """``lm0_x, lm0_y, lm1_x, ...`` for ``n`` landmarks."""
    return [f"lm{i}_{a}" for i in range(n) for a in "xy"]


def landmark_count(columns) -> int:
    """Number of consecutive ``lm{i}_x/lm{i}_y`` pairs present, starting at 0."""
    cols = set(columns)
    n = 0
    while f"lm{n}_x" in cols and f"lm{n}_y" in cols:
        n += 1
    return n


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




def arrow_table(cols: dict, schema=None):
    """A pyarrow Table from name -> array (numpy, list or Arrow); object arrays become strings."""
    import pyarrow as pa

    arrays = []
    for v in cols.values():
        if not isinstance(v, (pa.Array, pa.ChunkedArray)):
            v = np.asarray(v)
            v = pa.array(v, type=pa.string()) if v.dtype == object else pa.array(v)
        arrays.append(v)
    t = pa.Table.from_arrays(arrays, names=list(cols))
    return t.cast(schema) if schema is not None else t
