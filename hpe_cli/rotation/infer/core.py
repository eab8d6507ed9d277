"""The search space and its scoring: candidate systems, samples, scores, built-in names, reports."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..check import rotation_reasons
from ..distances import angle_diff_deg, frobenius
from ..elemental import axis_rotation
from ..euler import lock_distance
from ..systems import ROLES, RotationSystem, Turn, builtin_systems

#: |cos b| (Tait-Bryan) or |sin b| (proper Euler) below which a decoder may be wrong (~5.7 deg from the lock)
LOCK_ZONE = 0.1
#: an exact fit must explain at least this fraction of the samples
MIN_EXPLAINED = 0.9
#: default matching tolerance on the Frobenius error for code (float32 code gives ~3e-7)
CODE_TOL = 1e-6
#: default tolerance for tables (float32 storage, angles printed with a few decimals)
DATA_TOL = 1e-4
#: built-in names preferred when several share one function
PRIORITY = ("300w_lp", "6drepnet", "3ddfa_v2", "scipy_zyx", "opencv", "whenet")
#: at most this many rows enter the full search; the leaders are then checked on every row
SEARCH_ROWS = 512

SEQUENCES = ("xyz", "xzy", "yxz", "yzx", "zxy", "zyx", "xyx", "xzx", "yxy", "yzy", "zxz", "zyz")
_AXIS = {"x": 0, "y": 1, "z": 2}
#: role name -> its column in role order (pitch 0, yaw 1, roll 2)
ROLE_INDEX = {r: n for n, r in enumerate(ROLES)}


class CallError(ValueError):
    """The user's callable raised or returned something unusable."""


# --------------------------------------------------------------------------- candidates
@dataclass(frozen=True)
class Candidate:
    """One angles-to-matrix function: three turns in intrinsic (left-to-right product) order."""

    roles: tuple
    axes: str
    hands: tuple

    @property
    def turns(self) -> tuple:
        return tuple(Turn(r, a, h) for r, a, h in zip(self.roles, self.axes, self.hands))

    @property
    def proper(self) -> bool:
        return self.axes[0] == self.axes[2]

    @property
    def middle_role(self) -> str:
        return self.roles[1]

    def key(self) -> tuple:
        return self.roles, self.axes, self.hands

    def transpose(self) -> Candidate:
        flip = {"right": "left", "left": "right"}
        return Candidate(self.roles[::-1], self.axes[::-1], tuple(flip[h] for h in self.hands[::-1]))

    def formula(self) -> str:
        """E.g. ``R = Rz(roll) @ Ry(-yaw) @ Rx(pitch)`` (a left-handed turn is a negated angle)."""
        return "R = " + " @ ".join(
            f"R{a}({'-' if h == 'left' else ''}{r})" for r, a, h in zip(self.roles, self.axes, self.hands)
        )

    def words(self) -> str:
        def seq(turns):
            return ", then ".join(f"{t.angle} about {t.axis} ({t.hand}-handed)" for t in turns)

        return (
            f"intrinsic {'-'.join(self.axes.upper())}: {seq(self.turns)}; equivalently extrinsic "
            f"{'-'.join(self.axes[::-1].upper())}: {seq(self.turns[::-1])}"
        )

    def default_selection(self) -> str:
        return "proper" if self.proper else "tait_bryan"

    def system(
        self,
        name: str = "custom",
        description: str = "",
        *,
        order=ROLES,
        units: str = "degrees",
        selection: str | None = None,
        frame=None,
        storage: str = "active",
        notes: str = "",
    ) -> RotationSystem:
        """A :class:`RotationSystem` whose ``from_angles`` is this function."""
        selection = selection or self.default_selection()
        ranges = {r: (-180.0, 180.0) for r in ROLES}
        if selection == "tait_bryan":
            ranges[self.middle_role] = (-90.0, 90.0)
        elif selection == "proper":
            ranges[self.middle_role] = (0.0, 180.0)
        else:  # whenet: |pitch| < 90 and |roll| < 90
            ranges["pitch"] = ranges["roll"] = (-90.0, 90.0)
        frame = tuple(map(tuple, np.eye(3))) if frame is None else tuple(tuple(map(float, r)) for r in frame)
        return RotationSystem(
            name=name,
            description=description or self.formula(),
            frame=frame,
            turns=self.turns,
            sequence="intrinsic",
            storage=storage,
            order=tuple(order),
            units=units,
            ranges=ranges,
            selection=selection,
            notes=notes,
        )


@lru_cache(maxsize=1)
def candidates() -> tuple:
    """The 576 distinct candidate functions (see the module docstring)."""
    out = []
    for seq in SEQUENCES:
        for roles in itertools.permutations(ROLES):
            for hands in itertools.product(("right", "left"), repeat=3):
                out.append(Candidate(roles, seq, hands))
    return tuple(out)


@lru_cache(maxsize=1)
def _codes() -> np.ndarray:
    """(C, 3 positions, 3) int: role index, axis index, hand (0 right, 1 left)."""
    return np.array(
        [
            [[ROLE_INDEX[r], _AXIS[a], int(h == "left")] for r, a, h in zip(c.roles, c.axes, c.hands)]
            for c in candidates()
        ],
        dtype=np.intp,
    )


@lru_cache(maxsize=1)
def candidate_index() -> dict:
    """Candidate key -> its position in :func:`candidates`."""
    return {c.key(): n for n, c in enumerate(candidates())}


def candidate_of(system: RotationSystem) -> Candidate:
    """The candidate equal to ``system.from_angles``."""
    t = system._intrinsic_turns()
    return Candidate(tuple(x.angle for x in t), "".join(x.axis for x in t), tuple(x.hand for x in t))


def candidate_matrices(pyr_deg, index=None) -> np.ndarray:
    """Matrices ``(C, N, 3, 3)`` of candidates ``index`` (all by default) at angles ``(N, 3)`` (role order, deg)."""
    pyr = np.asarray(pyr_deg, dtype=np.float64).reshape(-1, 3)
    rad = np.deg2rad(pyr)
    n = len(pyr)
    elem = np.empty((3, 3, 2, n, 3, 3))
    for role in range(3):
        for axis in range(3):
            elem[role, axis, 0] = axis_rotation(axis, rad[:, role])
            elem[role, axis, 1] = np.swapaxes(elem[role, axis, 0], -1, -2)
    codes = _codes() if index is None else _codes()[np.atleast_1d(index)]
    e = [elem[codes[:, k, 0], codes[:, k, 1], codes[:, k, 2]] for k in range(3)]
    return np.matmul(np.matmul(e[0], e[1]), e[2])


def candidate_locks(R, index=None) -> np.ndarray:
    """Lock distance of matrices ``R`` (N, 3, 3) in each candidate's own sequence: ``(C, N)``."""
    R = np.asarray(R, dtype=np.float64)
    per_seq = np.stack([lock_distance(R, s) for s in SEQUENCES])
    seq_of = np.repeat(np.arange(len(SEQUENCES)), len(candidates()) // len(SEQUENCES))
    if index is not None:
        seq_of = seq_of[np.atleast_1d(index)]
    return per_seq[seq_of]


# --------------------------------------------------------------------------- samples
def spread_angles(n: int = 64, seed: int = 0) -> np.ndarray:
    """``n`` well-spread ``(pitch, yaw, roll)`` triples over the full circle, degrees.

    A scrambled stratified design: each angle takes one value in each of ``n``
    equal bins of (-180, 180), the bins shuffled independently per role, so no
    role is ever confined to a narrow range and no two samples coincide.
    """
    rng = np.random.default_rng(seed)
    u = (np.arange(n)[:, None] + rng.uniform(0.05, 0.95, size=(n, 3))) / n
    for k in range(3):
        u[:, k] = rng.permutation(u[:, k])
    return -180.0 + 360.0 * u


def random_rotations(n: int = 256, seed: int = 0) -> np.ndarray:
    """``n`` uniformly distributed rotation matrices (from normalised Gaussian quaternions)."""
    q = np.random.default_rng(seed).normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


# --------------------------------------------------------------------------- scoring
@dataclass
class Scores:
    """Per-candidate errors on the samples and the ranking they give."""

    index: np.ndarray  # (C,) candidate indices scored
    err: np.ndarray  # (C, N) Frobenius error
    excused: np.ndarray  # (C, N) bool: unexplained but inside the lock zone
    tol: float

    def __post_init__(self):
        self.explained = self.err <= self.tol  # NaN counts as unexplained
        self.unexplained = ~self.explained & ~self.excused
        self.n_bad = self.unexplained.sum(1)
        with np.errstate(invalid="ignore"):
            e = np.where(np.isfinite(self.err), self.err, np.inf)
        self.median = np.median(e, axis=1)
        self.max = np.max(np.where(self.excused, 0.0, e), axis=1)
        self.order = np.lexsort((self.median, self.n_bad))

    def exact(self, pos: int) -> bool:
        n = self.err.shape[1]
        return bool(self.n_bad[pos] == 0 and self.explained[pos].sum() >= MIN_EXPLAINED * n)

    def pos_of(self, cand_index: int) -> int:
        return int(np.flatnonzero(self.index == cand_index)[0])


def score(err, tol: float, locks=None, index=None) -> Scores:
    """Rank candidates by their errors ``(C, N)``; ``locks`` (C, N) excuses lock-zone samples."""
    err = np.asarray(err, dtype=np.float64)
    excused = np.zeros(err.shape, bool) if locks is None else (np.asarray(locks) < LOCK_ZONE) & ~(err <= tol)
    idx = np.arange(err.shape[0]) if index is None else np.asarray(index)
    return Scores(idx, err, excused, tol)


# --------------------------------------------------------------------------- built-in names
def builtin_names_by_candidate() -> dict:
    """Candidate index -> every built-in whose stored matrix function (angles -> stored matrix) it is.

    Found by probing ``from_angles`` so that systems with improper frames or
    another storage kind (whose stored matrix may still be an Euler product,
    e.g. img2pose's ``F A F`` equals the opencv function) are listed too.
    """
    return dict(_builtin_names_by_candidate())


@lru_cache(maxsize=1)
def _builtin_names_by_candidate():
    probe = spread_angles(16, seed=11)
    cm = candidate_matrices(probe)
    out: dict = {}
    for name, s in builtin_systems().items():
        g = s.from_angles(probe)
        hit = np.flatnonzero(frobenius(cm, g[None]).max(1) < 1e-9)
        for h in hit[:1]:
            out.setdefault(int(h), []).append(name)
    return out


def builtin_canonical_by_candidate() -> dict:
    """Candidate index -> built-ins whose angles give that *canonical* matrix (``to_canonical(from_angles)``)."""
    probe = spread_angles(16, seed=7)
    cm = candidate_matrices(probe)
    out: dict = {}
    for name, s in builtin_systems().items():
        g = s.to_canonical(s.from_angles(probe))
        hit = np.flatnonzero(frobenius(cm, g[None]).max(1) < 1e-9)
        if hit.size:
            out.setdefault(int(hit[0]), []).append(name)
    return out


def rank_builtins(names, order=None, units=None, selection=None) -> list:
    """Built-in names sharing one function, best first: systems storing angles, then those whose selection,
    argument order and units match the code's, then :data:`PRIORITY`, then by name."""
    systems = builtin_systems()

    def key(n):
        s = systems[n]
        return (
            s.storage_kind != "angles" or s.angle_frame != "system",  # systems that store angles first
            selection is not None and s.selection != selection,
            order is not None and tuple(s.order) != tuple(order),
            units is not None and s.units != units,
            PRIORITY.index(n) if n in PRIORITY else len(PRIORITY),
            n,
        )

    return sorted(names, key=key)


# --------------------------------------------------------------------------- code adapters


# --------------------------------------------------------------------------- reports
def _entry(cand_index: int, sc: Scores, stored: dict, canonical: dict | None = None) -> dict:
    pos = sc.pos_of(cand_index)
    c = candidates()[cand_index]
    t_index = candidate_index()[c.transpose().key()]
    e = {
        "formula": c.formula(),
        "turns": c.words(),
        "builtins": stored.get(cand_index, []),
        "transpose_of": stored.get(t_index, []),
        "max_error": float(sc.max[pos]),
        "median_error": float(sc.median[pos]),
        "explained": int(sc.explained[pos].sum()),
        "excused_near_lock": int(sc.excused[pos].sum()),
        "unexplained": int(sc.n_bad[pos]),
    }
    if canonical is not None:
        e["builtins_canonical"] = canonical.get(cand_index, [])
    return e


def _runners_up(sc: Scores, stored: dict, best_pos: int, k: int = 5) -> list:
    return [_entry(int(sc.index[p]), sc, stored) for p in sc.order if p != best_pos][:k]


def _probe_subsets(seed: int = 1, per: int = 16):
    rng = np.random.default_rng(seed)
    for size in (1, 2, 3):
        for subset in itertools.combinations(range(3), size):
            pyr = np.zeros((per, 3))
            for k in subset:
                pyr[:, k] = rng.uniform(10, 60, per) * rng.choice([-1.0, 1.0], per)
            yield [ROLES[k] for k in subset], pyr


def _breaks_summary(rows: list) -> str:
    ok = ["{" + ", ".join(r["nonzero"]) + "}" for r in rows if r["exact"]]
    bad = []
    for r in rows:
        if not r["exact"]:
            extra = f"; wrong: {', '.join(r['wrong_angles'])}" if r.get("wrong_angles") else ""
            bad.append("{" + ", ".join(r["nonzero"]) + "}" + f" (max error {r['max_error']:.3g}{extra})")
    parts = []
    if ok:
        parts.append("agrees when only these angles are non-zero: " + ", ".join(ok))
    if bad:
        parts.append("breaks when these are non-zero: " + ", ".join(bad))
    return "; ".join(parts) or "no structured probe could be evaluated"


def probe_builder(build, cand: Candidate, tol: float) -> dict:
    """Where a builder departs from candidate ``cand`` (subsets of non-zero angles)."""
    idx = candidate_index()[cand.key()]
    rows = []
    for roles, pyr in _probe_subsets():
        err = frobenius(build(pyr), candidate_matrices(pyr, idx)[0])
        rows.append({"nonzero": roles, "exact": bool(np.all(err <= tol)), "max_error": float(np.nanmax(err))})
    return {"candidate": cand.formula(), "summary": _breaks_summary(rows), "probes": rows}


def probe_decoder(decode, cand: Candidate, tol: float) -> dict:
    """Where a decoder departs from candidate ``cand``: rebuild error and which output angles are wrong."""
    idx = candidate_index()[cand.key()]
    sysm = cand.system("probe")
    atol = max(1e-6, float(np.rad2deg(tol)) * 10)
    rows = []
    for roles, pyr in _probe_subsets():
        R = candidate_matrices(pyr, idx)[0]
        d = decode(R)
        err = frobenius(candidate_matrices(d, idx)[0], R)
        p1, p2, _, lock = sysm.to_angles(R)
        d1, d2 = angle_diff_deg(d, p1), angle_diff_deg(d, p2)
        near = np.where((d1.sum(1) <= d2.sum(1))[:, None], d1, d2)
        ok_lock = lock >= LOCK_ZONE  # the angles are not unique at the lock: judge them elsewhere only
        wrong = [ROLES[k] for k in range(3) if np.any((near[:, k] > atol) & ok_lock)]
        rows.append(
            {
                "nonzero": roles,
                "exact": bool(np.all(err <= tol)),
                "max_error": float(np.nanmax(err)),
                "wrong_angles": wrong,
            }
        )
    return {"candidate": cand.formula(), "summary": _breaks_summary(rows), "probes": rows}


def selection_of(cand: Candidate, R, decoded, tol: float):
    """Which solution rule the decoder follows: (selection, fraction of non-lock samples it matches)."""
    atol = max(1e-6, float(np.rad2deg(tol)) * 10)
    rules = ["proper" if cand.proper else "tait_bryan", "whenet"]
    best = (cand.default_selection(), 0.0)
    for rule in rules:
        p1, _, _, lock = cand.system("probe", selection=rule).to_angles(R)
        use = lock >= LOCK_ZONE
        if not use.any():
            continue
        frac = float(np.mean(angle_diff_deg(decoded[use], p1[use]).max(1) <= atol))
        if frac > best[1]:
            best = (rule, frac)
    return best


def assemble_report(
    mode: str,
    sc: Scores,
    *,
    roles,
    units,
    source,
    tol,
    n,
    name,
    frame,
    storage,
    selection=None,
    selection_fraction=None,
) -> dict:
    """The common part of a builder/decoder/table report, assembled from the scores ``sc``."""
    stored = builtin_names_by_candidate()
    best_pos = int(sc.order[0])
    best_idx = int(sc.index[best_pos])
    cand = candidates()[best_idx]
    exact = sc.exact(best_pos)
    n_exact = int(sum(sc.exact(int(p)) for p in sc.order[:8]))
    units_word = "radians" if units in ("rad", "radians") else "degrees"
    report = {
        "mode": mode,
        "source": source,
        "roles": list(roles),
        "units": units_word,
        "samples": int(n),
        "tolerance": tol,
        "candidates": len(candidates()),
        "fit": "exact" if exact else "none",
    }
    entry = _entry(best_idx, sc, stored)
    if not exact:
        report.update(
            best="none", max_error=entry["max_error"], best_partial=entry, runners_up=_runners_up(sc, stored, best_pos)
        )
        return report
    names = rank_builtins(entry["builtins"], order=tuple(roles), units=units_word, selection=selection)
    if names:
        base = builtin_systems()[names[0]]
        note = f"inferred from {source}: matches built-in {base.name}"
        changes = {}
        if selection is not None and selection != base.selection:
            # the function is the built-in's, but the code keeps the other solution: say so and keep the code's rule
            changes = {"selection": selection, "ranges": cand.system(selection=selection).ranges}
            note += f", except that it keeps the {selection} solution (the built-in keeps {base.selection})"
            report["selection_differs"] = note
        system = replace(
            base, order=tuple(roles), units=units_word, notes=(base.notes + " " if base.notes else "") + note, **changes
        )
        if system.definition() != base.definition():  # a built-in's name may only carry its own definition
            system = replace(system, name=name or f"{base.name}_as_inferred")
        best = base.name
    else:
        system = cand.system(
            name or "custom",
            f"inferred from {source}: {cand.formula()}",
            order=roles,
            units=units_word,
            selection=selection,
            frame=frame,
            storage=storage,
            notes="frame and storage are not observable from angles and matrices alone; "
            "set them to what the code means",
        )
        best = "custom"
    report.update(
        best=best,
        max_error=entry["max_error"],
        matched=entry,
        definition=system.describe(),
        system=system.to_dict(),
        runners_up=_runners_up(sc, stored, best_pos),
    )
    report["reproduced_by"] = names
    if len(names) > 1:
        report["also_matches"] = {
            "names": names[1:],
            "note": "same matrix from the same angles; these differ only "
            "in what the code cannot reveal (frame, storage, solution rule, storage order)",
        }
    if n_exact > 1:
        report["ambiguous"] = f"{n_exact} distinct functions fit these samples exactly; sample more varied angles"
    if selection is not None:
        report["selection"] = {"rule": selection, "fraction": selection_fraction}
    report["_system"] = system
    return report


def report_json(report: dict) -> dict:
    """The report without its in-memory objects (ready for :func:`hpe_cli.io.write_json`)."""
    return {k: v for k, v in report.items() if not k.startswith("_")}


def check_rotations(M, verb: str) -> None:
    """Raise :class:`CallError` (``"{verb} <reason> on sample i"``) unless ``M`` is (N, 3, 3) rotations."""

    M = np.asarray(M)
    if M.ndim != 3 or M.shape[1:] != (3, 3):
        raise CallError(f"expected matrices of shape (N, 3, 3), got {M.shape}")
    reasons = rotation_reasons(M, tol=1e-4)
    bad = np.flatnonzero(reasons != "")
    if bad.size:
        raise CallError(f"{verb} {reasons[bad[0]]} on sample {bad[0]} ({bad.size} of {len(M)} samples)")
