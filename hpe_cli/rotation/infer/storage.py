"""Decoders that return stored values (rotation vector, quaternion, 6-D, 9 entries) instead of angles."""

from __future__ import annotations

import numpy as np

from .. import storage as st
from ..distances import frobenius
from ..systems import builtin_systems, system_from_dict
from .code import CallError, prefer_vectorised, to_numpy
from .core import CODE_TOL, random_rotations

# --------------------------------------------------------------------------- decoders returning stored values
#: (kind, order or 6-D columns, number of values) searched for a decoder that returns no angles
STORAGE_FORMS = (
    [("rotvec", None, 3), ("quaternion", "wxyz", 4), ("quaternion", "xyzw", 4)]
    + [("6d", (i, j), 6) for i in range(3) for j in range(3) if i != j]
    + [("matrix", None, 9)]
)


def as_value_decoder(func):
    """Wrap ``func`` (3x3 matrix -> k numbers, per sample or batched) as ``(N, 3, 3) -> (N, k)``."""

    def per_sample(R):
        return np.stack([to_numpy(func(m)).reshape(-1) for m in R])

    def vectorised(R):
        out = to_numpy(func(R))
        if out.ndim != 2 or out.shape[0] != len(R):
            raise ValueError("not batched")
        return out

    def decode(R):
        R = np.asarray(R, dtype=np.float64)
        try:
            return prefer_vectorised(vectorised, per_sample, 1e-9, True)(R)
        except CallError:
            raise
        except Exception:  # noqa: BLE001 - the user's code may raise anything
            return per_sample(R)

    return decode


def _form_matrices(kind, arg, values):

    if kind == "rotvec":
        return st.rotvec_to_matrix(values)
    if kind == "quaternion":
        return st.quaternion_to_matrix(values, arg)
    if kind == "6d":
        return st.sixd_to_matrix(values, arg)
    return values.reshape(-1, 3, 3)


def _form_words(kind, arg, transposed):
    what = {
        "rotvec": "rotation vector (axis * angle, radians)",
        "quaternion": f"unit quaternion ({arg}, {'scalar first' if arg == 'wxyz' else 'scalar last'})",
        "6d": f"6-D: matrix column {arg[0] if arg else 0} then column {arg[1] if arg else 1}",
        "matrix": "3x3 matrix, row-major",
    }[kind]
    return f"{what} of the {'transpose of the ' if transposed else ''}matrix it is given"


def infer_storage_decoder(
    decode,
    *,
    n: int = 256,
    tol: float = CODE_TOL,
    seed: int = 0,
    source: str = "<callable>",
    name: str | None = None,
    frame=None,
    **_ignored,
) -> dict:
    """Which storage form a decoder returning no angles (matrix -> k numbers) writes.

    Tries every form of :data:`STORAGE_FORMS` with the right width, of the
    matrix given and of its transpose, and compares the *rotations* (so ``q``
    and ``-q``, or a rotation vector of angle pi with either axis sign, are
    equal). The answer is a system with that ``storage_kind`` (identity frame
    unless ``frame``: code cannot reveal its frame).
    """
    R = random_rotations(n, seed)
    out = np.asarray(decode(R), dtype=np.float64)
    k = out.shape[1] if out.ndim == 2 else 0
    tried = _try_forms(R, out, k, tol)
    report = {
        "mode": "storage_decoder",
        "source": source,
        "samples": len(R),
        "tolerance": tol,
        "values_per_sample": int(k),
        "candidates": len(tried),
    }
    if not tried:
        report.update(
            fit="none",
            best="none",
            max_error=float("inf"),
            best_partial={
                "formula": f"no storage form returns {k} numbers (rotvec 3, quaternion 4, 6-D 6, matrix 9)",
                "builtins": [],
                "explained": 0,
                "median_error": float("inf"),
            },
            runners_up=[],
        )
        return report
    tried.sort(key=lambda t: (t[0], -t[2]))
    best = tried[0]
    if best[0] > tol:
        report.update(
            fit="none",
            best="none",
            max_error=best[0],
            best_partial=_form_entry(best),
            runners_up=[_form_entry(t) for t in tried[1:4]],
        )
        return report
    kind, arg, transposed = best[3], best[4], best[5]
    same = [
        n_
        for n_, s in builtin_systems().items()
        if s.storage_kind == kind
        and (kind != "quaternion" or s.quaternion_order == arg)
        and (kind != "6d" or tuple(s.sixd_columns) == arg)
    ]
    system = _form_system(kind, arg, transposed, name=name, source=source, frame=frame)
    e = _form_entry(best)
    e["builtins"] = same
    report.update(
        fit="exact",
        best=system.name,
        max_error=best[0],
        matched=e,
        definition=system.describe(),
        system=system.to_dict(),
        runners_up=[_form_entry(t) for t in tried[1:4]],
        reproduced_by=same,
        storage_form={"kind": kind, "order": arg, "transposed": transposed},
    )
    if same:
        report["also_matches"] = {
            "names": same,
            "note": "built-ins storing the same form (their frame and storage may differ: code cannot reveal them)",
        }
    report["_system"] = system
    return report


def _try_forms(R, out, k: int, tol: float) -> list:
    """Every storage form of width ``k``, of the matrix and of its transpose, against the decoder's ``out``:
    ``(max error, median error, samples within tol, kind, order or columns, transposed)`` each."""
    tried = []
    for kind, arg, width in STORAGE_FORMS:
        if width != k:
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            M = _form_matrices(kind, arg, out)
        for transposed in (False, True):
            ref = np.swapaxes(R, -1, -2) if transposed else R
            err = frobenius(M, ref)
            err = np.where(np.isfinite(err), err, np.inf)
            tried.append((float(np.max(err)), float(np.median(err)), int((err <= tol).sum()), kind, arg, transposed))
    return tried


def _form_entry(t) -> dict:
    """A report entry of one tried form (a tuple of :func:`_try_forms`)."""
    return {
        "formula": _form_words(t[3], t[4], t[5]),
        "max_error": t[0],
        "median_error": t[1],
        "explained": t[2],
        "builtins": [],
        "turns": f"storage_kind {t[3]}",
        "transpose_of": [],
    }


def _form_system(kind, arg, transposed, *, name, source, frame):
    """The system of the matched form (identity frame unless ``frame``: code cannot reveal its frame)."""
    d = {
        "name": name or "custom",
        "description": f"inferred from {source}: {_form_words(kind, arg, transposed)}",
        "storage_kind": kind,
        "storage": "transposed" if transposed else "active",
        "notes": "frame is not observable from code alone; set it to what the code means",
    }
    if frame is not None:
        d["frame"] = [list(map(float, r)) for r in frame]
    if kind == "quaternion":
        d["quaternion_order"] = arg
    if kind == "6d":
        d["sixd_columns"] = list(arg)
    return system_from_dict(d, source)
