"""Decoders (matrix -> angles, such as 3DDFA_V2's ``matrix2angle``): adapting user code and the search."""

from __future__ import annotations

import numpy as np

from ..distances import frobenius
from ..systems import ROLES
from .code import CallError, prefer_vectorised, to_numpy
from .core import (
    CODE_TOL,
    MIN_EXPLAINED,
    ROLE_INDEX,
    assemble_report,
    candidate_index,
    candidate_locks,
    candidate_matrices,
    candidates,
    probe_decoder,
    random_rotations,
    score,
    selection_of,
)


def as_decoder(func, roles=ROLES, units: str = "radians"):
    """Wrap ``func(R 3x3) -> three angles`` as ``decode(R (N, 3, 3)) -> (N, 3)`` role order, degrees.

    ``roles`` names the role of each returned angle, in the order returned.
    """
    cols = [ROLE_INDEX[r] for r in roles]
    conv = np.rad2deg if units == "radians" else (lambda a: a)

    def reorder(vals):
        out = np.empty_like(vals)
        out[:, cols] = conv(vals)
        return out

    def per_sample(R):
        vals = np.empty((len(R), 3))
        for n, m in enumerate(R):
            try:
                v = to_numpy(func(m.copy()))
            except Exception as exc:  # noqa: BLE001 - the user's code may raise anything
                raise CallError(
                    f"raised {type(exc).__name__} on matrix row {n}: {' '.join(str(exc).split())[:200]}"
                ) from None
            if v.size != 3:
                raise CallError(f"expected three angles, got shape {v.shape}")
            vals[n] = v.reshape(3)
        return reorder(vals)

    def vectorised(R):
        try:
            v = to_numpy(func(R.copy()))
        except Exception:  # noqa: BLE001 - the user's code may raise anything
            return None
        n = len(R)
        if v.shape == (3, n):
            v = v.T
        return reorder(v) if v.shape == (n, 3) else None

    def decode(R):
        return dispatch(np.asarray(R, dtype=np.float64).reshape(-1, 3, 3))

    dispatch = prefer_vectorised(vectorised, per_sample, atol=1e-7, equal_nan=True)
    decode.state = dispatch.state
    return decode


def infer_decoder(
    decode,
    *,
    roles=ROLES,
    units="radians",
    n: int = 256,
    tol: float = CODE_TOL,
    seed: int = 0,
    source: str = "<callable>",
    name: str | None = None,
    frame=None,
    storage: str = "active",
    rotations=None,
) -> dict:
    """Find the system whose ``from_angles`` rebuilds the matrices a decoder was given.

    ``decode`` maps ``(N, 3, 3)`` -> ``(N, 3)`` angles (role order, degrees);
    see :func:`as_decoder`. Samples in a candidate's lock zone may be
    unexplained (they are reported); everything else must rebuild within
    ``tol``. The decoder's choice among the two solutions sets the selection.
    ``rotations`` (M, 3, 3), when given, replaces the ``n`` random rotations.
    """
    R = random_rotations(n, seed) if rotations is None else np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    n = len(R)
    d = decode(R)
    sc = score(frobenius(candidate_matrices(d), R[None]), tol, locks=candidate_locks(R))
    best = candidates()[int(sc.index[sc.order[0]])]
    sel = frac = None
    if sc.exact(int(sc.order[0])):
        sel, frac = selection_of(best, R, d, tol)
        if frac < MIN_EXPLAINED:
            sel = None
    rep = assemble_report(
        "decoder",
        sc,
        roles=roles,
        units=units,
        source=source,
        tol=tol,
        n=n,
        name=name,
        frame=frame,
        storage=storage,
        selection=sel,
        selection_fraction=frac,
    )
    if rep["fit"] == "exact":
        if sel is None:
            rep["selection"] = {
                "rule": "none",
                "fraction": frac,
                "note": "the decoder's choice between the two solutions follows no known rule",
            }
        pos = sc.pos_of(candidate_index()[best.key()])
        exc = np.flatnonzero(sc.excused[pos])
        if exc.size:
            rep["near_lock"] = {
                "count": int(exc.size),
                "max_error": float(sc.err[pos, exc].max()),
                "note": "samples within ~5.7 deg of gimbal lock that the decoder handles its own way",
            }
    else:
        rep["best_partial"]["breaks"] = probe_decoder(decode, best, tol)
    return rep
