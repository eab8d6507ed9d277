"""Tables of angles with their matrices (a dataset's labels): the search on rows."""

from __future__ import annotations

import numpy as np

from ..check import rotation_mask
from ..distances import frobenius
from ..systems import ROLES
from .core import (
    DATA_TOL,
    MIN_EXPLAINED,
    SEARCH_ROWS,
    assemble_report,
    builtin_names_by_candidate,
    candidate_locks,
    candidate_matrices,
    candidates,
    score,
    selection_of,
)


def infer_table(
    pyr_deg,
    R,
    *,
    roles=ROLES,
    units="degrees",
    tol: float = DATA_TOL,
    source: str = "<table>",
    name: str | None = None,
    frame=None,
    storage: str = "active",
    seed: int = 0,
) -> dict:
    """Same search on a table of angles (role order, degrees) with their stored matrices.

    Rows in a candidate's lock zone may disagree (labels there are often
    decoded imprecisely). At most :data:`SEARCH_ROWS` rows enter the search;
    the leaders are then checked on every row.
    """

    pyr = np.asarray(pyr_deg, dtype=np.float64).reshape(-1, 3)
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    finite = np.isfinite(pyr).all(1) & np.isfinite(R).all((1, 2))
    ok = finite & rotation_mask(R)
    pyr, R = pyr[ok], R[ok]
    if len(pyr) == 0:
        raise ValueError("no row has finite angles and a rotation matrix")
    sub = np.arange(len(pyr))
    if len(sub) > SEARCH_ROWS:
        sub = np.sort(np.random.default_rng(seed).choice(len(pyr), SEARCH_ROWS, replace=False))
    sc = score(frobenius(candidate_matrices(pyr[sub]), R[sub][None]), tol, locks=candidate_locks(R[sub]))
    if len(sub) < len(pyr):
        lead = np.unique(np.concatenate([sc.order[:8], list(builtin_names_by_candidate())]))
        err = np.concatenate(
            [
                frobenius(candidate_matrices(pyr[a : a + 65536], lead), R[a : a + 65536][None])
                for a in range(0, len(pyr), 65536)
            ],
            axis=1,
        )
        locks = np.concatenate([candidate_locks(R[a : a + 65536], lead) for a in range(0, len(pyr), 65536)], axis=1)
        sc = score(err, tol, locks=locks, index=lead)
    sel = frac = None
    if sc.exact(int(sc.order[0])):  # labels are usually a decoder's output: which solution do they keep?
        sel, frac = selection_of(candidates()[int(sc.index[sc.order[0]])], R, pyr, tol)
        sel = sel if frac >= MIN_EXPLAINED else None
    rep = assemble_report(
        "table",
        sc,
        roles=roles,
        units=units,
        source=source,
        tol=tol,
        n=len(pyr),
        name=name,
        frame=frame,
        storage=storage,
        selection=sel,
        selection_fraction=frac,
    )
    rep["rows_skipped"] = {"non_finite": int((~finite).sum()), "not_a_rotation": int((finite & ~ok).sum())}
    if rep["fit"] != "exact":
        pos = int(sc.order[0])
        bad = np.flatnonzero(sc.unexplained[pos])
        worst = bad[np.argsort(-sc.err[pos, bad])][:10]
        rep["best_partial"]["worst_rows"] = [int(i) for i in np.flatnonzero(ok)[worst]]
    return rep
