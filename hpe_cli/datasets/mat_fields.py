"""Type and shape checks of the variables of a 300W-LP / AFLW2000-3D ``.mat`` file, at the door.

``scipy.io.loadmat`` returns a MATLAB cell array as an object array, a struct as a structured
(``void``) array, a char array as a str array, a sparse matrix as a ``scipy.sparse`` object and a
logical as a bool array. Only real numeric arrays are labels; anything else is refused here with one
line naming the file and the variable (``x.mat: Pose_Para: expected a 1x7 numeric array, got a cell
array``), before :mod:`hpe_cli.datasets.mat` converts the values.
"""

from __future__ import annotations

import numpy as np

from ..errors import HpeError

#: variable -> (what is expected, smallest number of values)
EXPECTED = {
    "Pose_Para": ("a 1x7 numeric array (pitch, yaw, roll, tdx, tdy, tdz, scale)", 3),
    "pt2d": ("a 2xN numeric array", 0),
    "pt3d_68": ("a 3x68 numeric array", 0),
    "pts_2d": ("a 68x2 numeric array", 0),
    "pts_3d": ("a 68x2 or 68x3 numeric array", 0),
}


def matlab_kind(value) -> str:
    """What MATLAB type a ``loadmat`` value was: cell array, struct, char array, sparse, logical, ..."""
    if isinstance(value, np.ndarray):
        kind = value.dtype.kind
        if kind == "O":
            return f"a cell array {value.shape}"
        if kind == "V":
            return "a struct"
        if kind in "US":
            return f"a char array {str(value.reshape(-1)[:1].tolist())[:40]}" if value.size else "an empty char array"
        if kind == "b":
            return f"a logical array {value.shape}"
        if kind == "c":
            return f"a complex array {value.shape}"
        return f"a {value.dtype} array {value.shape}"
    if hasattr(value, "tocoo"):
        return "a sparse matrix"
    return type(value).__name__


def check_fields(m: dict, path) -> dict:
    """Refuse any label variable of ``m`` (a ``loadmat`` dict) that is not a real numeric array.

    Returns ``m`` with those variables as float64 arrays. Raises :class:`HpeError`
    ``"PATH: VARIABLE: expected ..., got a cell array (1, 7)"`` otherwise; a
    ``Pose_Para`` with more than 7 or fewer than 3 values, or NaN/inf angles
    given as non-numbers, is refused the same way.
    """
    out = dict(m)
    for key, (want, least) in EXPECTED.items():
        if key not in m:
            continue
        v = m[key]
        if not isinstance(v, np.ndarray) or v.dtype.kind not in "fiu":
            raise HpeError(f"{path}: {key}: expected {want}, got {matlab_kind(v)}")
        arr = v.astype(np.float64)
        if key == "Pose_Para" and (
            arr.size < least or arr.size > 7 or arr.ndim > 2 or (arr.ndim == 2 and min(arr.shape) != 1)
        ):
            raise HpeError(f"{path}: {key}: expected {want}, got shape {arr.shape}")
        if key != "Pose_Para" and arr.ndim != 2:
            raise HpeError(f"{path}: {key}: expected {want}, got shape {arr.shape}")
        out[key] = arr
    return out


__all__ = ["check_fields", "matlab_kind"]
