"""Builders (angles -> matrix, such as 6DRepNet's ``get_R``): adapting user code and the search."""

from __future__ import annotations

import numpy as np

from ..distances import frobenius
from ..systems import ROLES
from .core import (
    CODE_TOL,
    ROLE_INDEX,
    CallError,
    assemble_report,
    candidate_matrices,
    candidates,
    check_rotations,
    probe_builder,
    score,
    spread_angles,
)


# --------------------------------------------------------------------------- code adapters
def to_numpy(out) -> np.ndarray:
    """User code's result (NumPy, torch tensors, sequences of either) as a float64 array."""
    if hasattr(out, "detach"):  # a torch tensor, without importing torch
        out = out.detach().cpu().numpy()
    if isinstance(out, (tuple, list)):
        out = [o.detach().cpu().numpy() if hasattr(o, "detach") else o for o in out]
    return np.asarray(out, dtype=np.float64)


def as_builder(func, roles=ROLES, units: str = "radians", packed: bool = False):
    """Wrap ``func(*angles) -> 3x3`` as ``build(pyr_deg (N, 3)) -> (N, 3, 3)``.

    ``roles`` names the role of each positional argument; ``units`` the units
    ``func`` expects; ``packed``: ``func`` takes one sequence of three angles.
    The first call tries one vectorised call (arrays in, ``(N, 3, 3)`` or
    ``(3, 3, N)`` out) and checks it against per-sample calls on two samples;
    otherwise every later call goes sample by sample.
    """
    cols = [ROLE_INDEX[r] for r in roles]
    conv = np.deg2rad if units == "radians" else (lambda a: a)

    def call(args):
        return func(np.stack(args)) if packed else func(*args)

    def per_sample(pyr):
        out = np.empty((len(pyr), 3, 3))
        for n, row in enumerate(pyr):
            args = [float(conv(row[c])) for c in cols]
            try:
                m = to_numpy(func(np.array(args)) if packed else func(*args))
            except Exception as exc:  # noqa: BLE001 - the user's code may raise anything
                raise CallError(
                    f"raised {type(exc).__name__} on angles {tuple(round(a, 6) for a in args)}: "
                    f"{' '.join(str(exc).split())[:200]}"
                ) from None
            if m.size != 9:
                raise CallError(f"expected a 3x3 matrix, got shape {m.shape}")
            out[n] = m.reshape(3, 3)
        return out

    def vectorised(pyr):
        try:
            m = to_numpy(call([conv(pyr[:, c]) for c in cols]))
        except Exception:  # noqa: BLE001 - the user's code may raise anything
            return None
        n = len(pyr)
        if m.shape == (n, 3, 3):
            return m
        if m.shape == (3, 3, n):
            return np.moveaxis(m, -1, 0)
        return None

    def build(pyr_deg):
        return dispatch(np.asarray(pyr_deg, dtype=np.float64).reshape(-1, 3))

    dispatch = prefer_vectorised(vectorised, per_sample, atol=1e-9, equal_nan=False)
    build.state = dispatch.state
    return build


def prefer_vectorised(vectorised, per_sample, atol: float, equal_nan: bool):
    """Call user code on whole arrays when it gives the per-sample answers, else row by row.

    The first call with more than 3 rows decides: the vectorised result is
    kept if it equals the per-sample result on two rows (or if only the
    vectorised form works), and the choice is remembered in ``.state``.
    """
    state = {"vectorised": None}

    def run(x):
        if state["vectorised"] is None:
            out = vectorised(x) if len(x) > 3 else None
            if out is not None:
                try:
                    ok = np.allclose(per_sample(x[:2]), out[:2], rtol=0, atol=atol, equal_nan=equal_nan)
                except CallError:
                    ok = True  # only the vectorised form works
                if ok:
                    state["vectorised"] = True
                    return out
            state["vectorised"] = False
            return per_sample(x)
        if state["vectorised"]:
            out = vectorised(x)
            if out is not None:
                return out
        return per_sample(x)

    run.state = state
    return run


def infer_builder(
    build,
    *,
    roles=ROLES,
    units="radians",
    n: int = 64,
    tol: float = CODE_TOL,
    seed: int = 0,
    source: str = "<callable>",
    name: str | None = None,
    frame=None,
    storage: str = "active",
) -> dict:
    """Find the system whose stored matrix function equals ``build``.

    Parameters
    ----------
    build : callable
        ``(N, 3)`` angles (role order, degrees) -> ``(N, 3, 3)`` matrices
        (see :func:`as_builder`).
    roles, units : describe the code's arguments (for the report and the system file).
    n, seed : number of well-spread samples and their seed.
    tol : float
        Largest Frobenius error accepted as equal.
    name, frame, storage :
        Used for a custom answer only (frame as a 3x3 nested sequence).

    Returns
    -------
    dict
        JSON-ready report (see :func:`report_json`); key ``_system`` holds the
        matched :class:`RotationSystem` when the fit is exact.
    """
    pyr = spread_angles(n, seed)
    M = build(pyr)
    check_rotations(M, "returned")
    sc = score(frobenius(candidate_matrices(pyr), M[None]), tol)
    rep = assemble_report(
        "callable", sc, roles=roles, units=units, source=source, tol=tol, n=n, name=name, frame=frame, storage=storage
    )
    if rep["fit"] != "exact":
        cand = candidates()[int(sc.index[sc.order[0]])]
        rep["best_partial"]["breaks"] = probe_builder(build, cand, tol)
    return rep
