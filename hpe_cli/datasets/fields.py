"""Field checks shared by the dataset readers: values read from a file are checked as what they are.

Every function returns ``""`` when the value is usable and otherwise the reason, phrased
``"FIELD: expected X, got Y"``; the reader prefixes the file and the record (``FILE: row 3, person
0: ...``, ``FILE: camera 7 (00_07): ...``) and raises :class:`~hpe_cli.errors.HpeError` or sets a
per-record reject. Nothing here raises on a malformed value (wrong type, shape, ``None``, strings,
nested lists): that is the point.

Camera data
-----------
- rotations: finite, orthonormal (``||R R^T - I||_F <= tol``) and ``det R = +1``;
- intrinsics ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]``: finite, ``fx, fy > 0`` and, when the image
  size is known, the principal point inside the image (``0 <= cx <= width``, ``0 <= cy <= height``;
  lens makers centre the sensor on the optical axis within a few percent, and every published
  calibration we know of has it within 10 % of the centre);
- distortion, OpenCV's model (``k1, k2, p1, p2[, k3]``; OpenCV ``calib3d`` "Camera Calibration and
  3D Reconstruction": ``x_d = x g(r) + 2 p1 x y + p2 (r^2 + 2 x^2)``, ``g(r) = 1 + k1 r^2 + k2 r^4 +
  k3 r^6``), see :data:`MAX_TANGENTIAL` and :func:`distortion_problem`. The bound is stated over the
  image, not per coefficient, because what makes a lens model real is what it does inside the picture:
  over every normalised radius ``r`` the image reaches (its corners through ``K^-1``), the radial
  factor ``g(r)`` stays within [1/4, 4] and the distorted radius ``r g(r)`` keeps growing with ``r``
  (a fold would map two directions onto one pixel, and OpenCV's ``projectPoints`` would put points
  from outside the field of view into the image). For reference, the 520 cameras of CMU Panoptic's
  ``160906_pizza1`` have ``|k| <= 0.54``, ``|p| <= 0.003`` and ``g`` within [0.94, 1.03] at their
  corners; BIWI's Kinect cameras have no distortion. A coefficient that the image cannot check
  (unknown size) is bounded by :data:`MAX_RADIAL` instead.
"""

from __future__ import annotations

import numpy as np

#: ||R R^T - I||_F accepted for a rotation stored with 6 printed digits (Panoptic, BIWI)
ROTATION_TOL = 1e-4
#: radial factor g(r) allowed anywhere inside the image: no 5-coefficient lens squeezes or stretches by 4x
RADIAL_FACTOR = (0.25, 4.0)
#: |p1|, |p2| above this are not a lens's decentering (real ones are ~1e-3; 0.1 moves the corner by ~10 %)
MAX_TANGENTIAL = 0.1
#: |k1|, |k2|, |k3| above this are refused outright (the image check is the real test; Panoptic's largest is 0.54)
MAX_RADIAL = 1000.0
#: frame numbers above this are not a recording: 2^31 - 1 frames are 2.3 years at 29.97 fps
MAX_FRAME = 2**31 - 1


def describe(value) -> str:
    """A short, one-line name of what a value is (``str 'no'``, ``None``, ``a (2, 3) array of str``)."""
    return " ".join(_describe(value).split())


def _describe(value) -> str:
    if value is None:
        return "None"
    if isinstance(value, (bool, np.bool_)):
        return f"bool {bool(value)}"
    if isinstance(value, str):
        return f"str {value[:40]!r}"
    if isinstance(value, (bytes, bytearray)):
        return f"bytes {bytes(value[:20])!r}"
    if isinstance(value, np.ndarray):
        kind = {
            "U": "str",
            "S": "bytes",
            "O": "objects",
            "V": "structs (a MATLAB struct)",
            "c": "complex numbers",
            "b": "bools",
        }.get(value.dtype.kind, str(value.dtype))
        return f"a {value.shape} array of {kind}"
    if isinstance(value, (list, tuple)):
        inner = {type(v).__name__ for v in value[:50]}
        return f"a {type(value).__name__} of {len(value)} ({', '.join(sorted(inner)) or 'empty'})"
    if isinstance(value, dict):
        return f"a dict (keys {', '.join(repr(k)[:20] for k in list(value)[:4])})"
    if isinstance(value, (int, float, np.integer, np.floating)):
        return f"{type(value).__name__} {value!r}"
    return type(value).__name__


def as_numbers(value, shape=None, min_size: int = 0):
    """``(array, "")`` of float64 when ``value`` is numbers of ``shape`` (None: any; -1: any length on that
    axis), else ``(None, why)``. Strings, bools, None, dicts, objects and ragged lists are refused."""
    arr = None
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        arr = value.astype(np.float64, copy=False)
    elif not isinstance(value, (str, bytes, bytearray, dict, bool, np.bool_)) and value is not None:
        try:
            with np.errstate(all="ignore"):
                raw = np.asarray(value)
            if (
                raw.dtype.kind in "fiu"
                or raw.dtype.kind == "O"
                and raw.size
                and all(
                    v is None
                    or (isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)))
                    for v in raw.reshape(-1).tolist()
                )
                and any(v is not None for v in raw.reshape(-1).tolist())
            ):
                # a null inside an array of numbers is a missing number (NaN), as a Parquet round trip writes NaN
                arr = np.where(raw == None, np.nan, raw).astype(np.float64)  # noqa: E711 (elementwise)
            elif raw.dtype.kind == "O" and raw.ndim == 1 and raw.size:
                # a nested sequence (what a Parquet round trip gives: an object array of per-row arrays):
                # numbers of one shape on every row, stacked; ragged rows or anything else is refused
                parts = [as_numbers(v)[0] if isinstance(v, (np.ndarray, list, tuple)) else None for v in raw.tolist()]
                if all(q is not None and q.shape == parts[0].shape for q in parts):
                    arr = np.stack(parts)
        except (ValueError, TypeError, OverflowError, RecursionError, MemoryError):
            arr = None
    if arr is None:
        return None, f"got {describe(value)}"
    if shape is not None:
        ok = arr.ndim == len(shape) and all(s == -1 or s == n for s, n in zip(shape, arr.shape))
        if not ok:
            return None, f"got shape {arr.shape}"
    if arr.size < min_size:
        return None, f"got {arr.size} values"
    return arr, ""


def shape_text(shape) -> str:
    return "(" + ", ".join("N" if s == -1 else str(s) for s in shape) + ")"


def numbers_or_why(value, field: str, shape=None, what: str | None = None):
    """:func:`as_numbers` with the whole reason: ``"FIELD: expected a (3, 3) array of numbers, got str 'x'"``."""
    arr, got = as_numbers(value, shape)
    if arr is None:
        want = what or (f"a {shape_text(shape)} array of numbers" if shape is not None else "numbers")
        return None, f"{field}: expected {want}, {got}"
    return arr, ""


def as_bool(value):
    """``(bool, "")`` for True/False (also numpy bools and the integers 0/1), else ``(None, why)``."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value), ""
    if isinstance(value, (int, np.integer)) and value in (0, 1):
        return bool(value), ""
    if isinstance(value, (float, np.floating)) and value in (0.0, 1.0):
        return bool(value), ""
    return None, f"got {describe(value)}"


def as_int(value, lo=None, hi=None):
    """``(int, "")`` for an integer (or an integral float) within [lo, hi], else ``(None, why)``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return None, f"got {describe(value)}"
    if isinstance(value, (float, np.floating)) and not (np.isfinite(value) and float(value).is_integer()):
        return None, f"got {value!r}"
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        return None, f"got {v}"
    return v, ""


def frame_number_problem(text: str) -> str:
    """Why a frame number written in a file name cannot be used ('' when it can)."""
    if len(text) > 12 or int(text) > MAX_FRAME:
        return f"frame number {text[:30]}{'...' if len(text) > 30 else ''} is out of range (expected 0 to {MAX_FRAME})"
    return ""


def rotation_problem(R, field: str = "R", tol: float = ROTATION_TOL) -> str:
    """'' for a finite 3x3 rotation (orthonormal within ``tol``, det +1), else the reason."""
    R = np.asarray(R, dtype=np.float64)
    if not np.isfinite(R).all():
        return f"{field}: expected a rotation matrix, got NaN or inf"
    with np.errstate(all="ignore"):
        err = float(np.linalg.norm(R @ R.T - np.eye(3)))
        det = float(np.linalg.det(R))
    if not err <= tol:
        return (
            f"{field}: expected a rotation matrix (orthonormal, det +1), got ||R R^T - I|| = {err:.3g} (det {det:.4g})"
        )
    if det < 0:
        return f"{field}: expected a rotation matrix (det +1), got det {det:.4g} (a reflection)"
    return ""


def intrinsics_problem(K, width=None, height=None, field: str = "K") -> str:
    """'' for pinhole intrinsics ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` with fx, fy > 0 and, when the
    image size is given, the principal point inside the image; else the reason."""
    K = np.asarray(K, dtype=np.float64)
    if not np.isfinite(K).all():
        return f"{field}: expected finite intrinsics, got NaN or inf"
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        return f"{field}: expected positive focal lengths fx, fy, got fx {K[0, 0]:g}, fy {K[1, 1]:g}"
    if K[2, 2] != 1 or K[2, 0] != 0 or K[2, 1] != 0 or K[1, 0] != 0:
        return f"{field}: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {np.round(K, 6).tolist()}"
    if width is not None and height is not None:
        cx, cy = K[0, 2], K[1, 2]
        if not (0 <= cx <= width and 0 <= cy <= height):
            return (
                f"{field}: expected the principal point inside the {int(width)}x{int(height)} image, "
                f"got ({cx:g}, {cy:g})"
            )
    return ""


def distortion_problem(dist, K=None, width=None, height=None, field: str = "distCoef") -> str:
    """'' for OpenCV distortion ``k1, k2, p1, p2[, k3]`` a real lens can have, else the reason.

    With ``K`` and the image size, the radial factor ``g(r)`` must stay in :data:`RADIAL_FACTOR` and
    ``r g(r)`` must increase over every radius the image reaches (see the module notes); ``|p1|, |p2|``
    at most :data:`MAX_TANGENTIAL`; ``|k1|, |k2|, |k3|`` at most :data:`MAX_RADIAL` in any case.
    """
    d = np.asarray(dist, dtype=np.float64).reshape(1, -1)
    if K is None or width is None or height is None:
        return distortion_problems(d, None, None, None, field)[0]
    return distortion_problems(
        d,
        np.asarray(K, dtype=np.float64)[None],
        np.array([width], dtype=np.float64),
        np.array([height], dtype=np.float64),
        field,
    )[0]


def distortion_problems(dist, K=None, width=None, height=None, field: str = "distCoef") -> list:
    """:func:`distortion_problem` of C cameras at once: ``dist`` (C, 4 or 5), ``K`` (C, 3, 3), sizes (C,)."""
    d = np.asarray(dist, dtype=np.float64)
    d = np.concatenate([d, np.zeros((len(d), 5))], axis=1)[:, :5]
    out = [""] * len(d)
    k1, k2, p1, p2, k3 = d.T
    fin = np.isfinite(d).all(axis=1)
    with np.errstate(all="ignore"):
        radial_big = np.maximum(np.maximum(np.abs(k1), np.abs(k2)), np.abs(k3)) > MAX_RADIAL
        tang_big = np.maximum(np.abs(p1), np.abs(p2)) > MAX_TANGENTIAL
        bad_shape = np.zeros(len(d), dtype=bool)
        g_at = np.full(len(d), np.nan)
        r_at = np.full(len(d), np.nan)
        fold = np.zeros(len(d), dtype=bool)
        if K is not None and len(d):
            K = np.asarray(K, dtype=np.float64)
            w, h = np.asarray(width, dtype=np.float64), np.asarray(height, dtype=np.float64)
            fx, s, cx, fy, cy = K[:, 0, 0], K[:, 0, 1], K[:, 0, 2], K[:, 1, 1], K[:, 1, 2]
            r_max = np.zeros(len(d))
            for u, v in ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)):  # the image corners through K^-1
                y = (v * h - cy) / fy
                x = (u * w - cx - s * y) / fx
                r_max = np.maximum(r_max, np.sqrt(x * x + y * y))
            r = r_max[:, None] * np.linspace(0.0, 1.0, 65)[None]
            r2 = r * r
            g = 1 + k1[:, None] * r2 + k2[:, None] * r2**2 + k3[:, None] * r2**3
            slope = 1 + 3 * k1[:, None] * r2 + 5 * k2[:, None] * r2**2 + 7 * k3[:, None] * r2**3
            lo, hi = RADIAL_FACTOR
            out_range = ~((g >= lo) & (g <= hi))
            bad_shape = out_range.any(axis=1) & np.isfinite(r_max)
            first = out_range.argmax(axis=1)
            g_at = g[np.arange(len(d)), first]
            r_at = r[np.arange(len(d)), first]
            folds = slope <= 0
            fold = folds.any(axis=1) & np.isfinite(r_max) & ~bad_shape
            r_fold = r[np.arange(len(d)), folds.argmax(axis=1)]
    for c in np.flatnonzero(~fin | radial_big | tang_big | bad_shape | fold):
        v = d[c].tolist()
        if not fin[c]:
            out[c] = f"{field}: expected finite distortion coefficients, got {v}"
        elif radial_big[c]:
            out[c] = f"{field}: expected radial coefficients |k1|, |k2|, |k3| <= {MAX_RADIAL:g} (a real lens), got {v}"
        elif tang_big[c]:
            out[c] = (
                f"{field}: expected tangential coefficients |p1|, |p2| <= {MAX_TANGENTIAL:g} (a real lens is "
                f"decentred by ~1e-3), got p1 {v[2]:g}, p2 {v[3]:g}"
            )
        elif bad_shape[c]:
            out[c] = (
                f"{field}: expected a lens model that scales image radii by {RADIAL_FACTOR[0]:g} to "
                f"{RADIAL_FACTOR[1]:g}, got a factor of {g_at[c]:.3g} at normalised radius {r_at[c]:.3g} "
                f"(inside the image; coefficients {v})"
            )
        else:
            out[c] = (
                f"{field}: expected a lens model that is one-to-one over the image, got one that folds back "
                f"at normalised radius {r_fold[c]:.3g} (coefficients {v})"
            )
    return out


def rotation_problems(R, field: str = "R", tol: float = ROTATION_TOL) -> list:
    """:func:`rotation_problem` of (C, 3, 3) matrices at once."""
    R = np.asarray(R, dtype=np.float64)
    out = [""] * len(R)
    with np.errstate(all="ignore"):
        fin = np.isfinite(R).all(axis=(1, 2))
        err = np.linalg.norm(R @ np.swapaxes(R, 1, 2) - np.eye(3), axis=(1, 2))
        det = np.linalg.det(np.where(fin[:, None, None], R, 0.0))
    for c in np.flatnonzero(~fin | ~(err <= tol) | (det < 0)):
        out[c] = rotation_problem(R[c], field, tol)
    return out


def name_problem(name, field: str = "name") -> str:
    """'' for a non-empty string, else the reason (None, numbers, '')."""
    if not isinstance(name, str):
        return f"{field}: expected a non-empty string, got {describe(name)}"
    if not name.strip():
        return f"{field}: expected a non-empty string, got {name!r}"
    return ""


def member_problem(name: str) -> str:
    """Why an archive member's name is refused ('' when fine): absolute, drive, '..' or NUL."""
    p = str(name).replace("\\", "/")
    if "\x00" in p:
        return "its name contains NUL"
    if p.startswith("/") or (len(p) > 1 and p[1] == ":"):
        return "an absolute name"
    if ".." in p.split("/"):
        return "a name with '..' (outside the archive)"
    return ""


__all__ = [
    "MAX_FRAME",
    "MAX_RADIAL",
    "MAX_TANGENTIAL",
    "RADIAL_FACTOR",
    "ROTATION_TOL",
    "as_bool",
    "as_int",
    "as_numbers",
    "describe",
    "distortion_problem",
    "distortion_problems",
    "frame_number_problem",
    "intrinsics_problem",
    "member_problem",
    "name_problem",
    "numbers_or_why",
    "rotation_problem",
    "rotation_problems",
]
