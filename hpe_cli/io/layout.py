"""The label table layout shared by every command."""

from __future__ import annotations

import numpy as np

from ..rotation.columns import ANGLE2_COLS, ANGLE_COLS, LABEL_COLS, MATRIX_COLS, conversion_columns  # noqa: F401

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


def string_array(values):
    """A pyarrow ``string`` array of Python strings (``None`` becomes null), built from its buffers.

    ``pa.array`` imports pandas on its first call (about 0.3 s, in every worker
    process); this does not. Anything but ``str``/``None`` is left to
    ``pa.array`` (same result and errors as before).
    """
    import pyarrow as pa  # lazy: start-up

    values = list(values)
    n = len(values)
    try:
        data = [s.encode("utf-8") if s is not None else b"" for s in values]
    except (AttributeError, UnicodeEncodeError):  # not all str: pa.array's own conversion and messages
        return pa.array(values, type=pa.string())
    lengths = np.fromiter(map(len, data), dtype=np.int64, count=n)
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    typ = pa.string()
    if offsets[-1] >= 2**31:
        typ = pa.large_string()
    else:
        offsets = offsets.astype(np.int32)
    validity = None
    nulls = [i for i, s in enumerate(values) if s is None]
    if nulls:
        ok = np.ones(n, dtype=bool)
        ok[nulls] = False
        validity = pa.py_buffer(np.packbits(ok, bitorder="little"))
    arr = pa.Array.from_buffers(
        typ, n, [validity, pa.py_buffer(offsets), pa.py_buffer(b"".join(data))], null_count=len(nulls)
    )
    return arr.cast(pa.string()) if typ != pa.string() else arr


#: numpy kinds whose buffers Arrow takes as they are (no copy, no pandas)
_PLAIN_KINDS = "iuf"


def numpy_to_arrow(v):
    """A pyarrow array of a 1-D numpy array (or list): numbers and booleans from their buffers, object
    arrays as strings (:func:`string_array`); anything else through ``pa.array``. Values are those
    ``pa.array`` gives (NaN stays NaN, not null)."""
    import pyarrow as pa  # lazy: start-up

    if isinstance(v, (pa.Array, pa.ChunkedArray)):
        return v
    v = np.asarray(v)
    if v.ndim == 1 and v.dtype.kind in _PLAIN_KINDS and v.dtype.isnative and v.dtype != np.float16:
        v = np.ascontiguousarray(v)
        typ = pa.from_numpy_dtype(v.dtype)
        return pa.Array.from_buffers(typ, len(v), [None, pa.py_buffer(v)], null_count=0)
    if v.ndim == 1 and v.dtype == bool:
        return pa.Array.from_buffers(
            pa.bool_(), len(v), [None, pa.py_buffer(np.packbits(v, bitorder="little"))], null_count=0
        )
    if v.ndim == 1 and v.dtype == object:
        return string_array(v)
    return pa.array(v)


def arrow_to_numpy(col, dtype=None) -> np.ndarray:
    """A numeric Arrow Array or ChunkedArray as a 1-D numpy array, read from its buffers (no pandas: Arrow's
    ``to_numpy`` imports it, 0.3 s in every worker process).

    ``dtype`` (optional) casts in Arrow first. Nulls become NaN (a float
    result) as with ``to_numpy(zero_copy_only=False)``; types that are not
    fixed-width numbers go through ``to_numpy``.
    """
    import pyarrow as pa  # lazy: start-up

    chunks = col.chunks if isinstance(col, pa.ChunkedArray) else [col]
    target = pa.from_numpy_dtype(np.dtype(dtype)) if dtype is not None else col.type
    parts = []
    for ch in chunks:
        if ch.type != target:
            ch = ch.cast(target)
        if not (pa.types.is_integer(ch.type) or pa.types.is_floating(ch.type)) or pa.types.is_float16(ch.type):
            parts.append(np.asarray(ch.to_numpy(zero_copy_only=False)))
            continue
        np_type = np.dtype(ch.type.to_pandas_dtype())
        v = (
            np.frombuffer(ch.buffers()[1], dtype=np_type, count=len(ch), offset=ch.offset * np_type.itemsize)
            if len(ch)
            else np.empty(0, dtype=np_type)
        )
        if ch.null_count:
            bits = np.unpackbits(np.frombuffer(ch.buffers()[0], dtype=np.uint8), bitorder="little")
            valid = bits[ch.offset : ch.offset + len(ch)].astype(bool)
            v = v.astype(np.float64) if np_type.kind != "f" else v.copy()
            v[~valid] = np.nan
        parts.append(v)
    if not parts:
        return np.empty(0, dtype=np.dtype(dtype) if dtype is not None else np.float64)
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def arrow_table(cols: dict, schema=None):
    """A pyarrow Table from name -> array (numpy, list or Arrow); object arrays become strings.

    Built from the arrays' buffers (:func:`numpy_to_arrow`), so making a table
    does not import pandas (a worker process would spend 0.3 s on it).
    """
    import pyarrow as pa  # lazy: start-up

    t = pa.Table.from_arrays([numpy_to_arrow(v) for v in cols.values()], names=list(cols))
    return t.cast(schema) if schema is not None else t
