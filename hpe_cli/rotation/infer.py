"""Infer the rotation system behind a piece of code or a labelled dataset.

What can be observed
--------------------
A system's angles-to-matrix map (:meth:`RotationSystem.from_angles`) depends
on its three turns only: which role (pitch, yaw, roll) each turn takes, about
which of the system's axes, with which hand, and in which order the turns are
composed. The frame ``B`` and the storage (active or transposed) never enter
``from_angles``; they only say how the stored matrix relates to the canonical
300W-LP matrix (``to_canonical``). Hence:

- a *builder* (angles -> matrix, such as 6DRepNet's ``get_R``) or a table of
  angles with their matrices reveals the turns and their order, but not the
  frame nor the storage. The answer is the built-in system whose *stored*
  function equals the code's (its frame comes with its name: a SciPy-style
  Z-Y-X builder is ``scipy_zyx``, which lives in the frame ``T``), or a custom
  system in the frame and storage the caller names (canonical and active by
  default);
- a *decoder* (matrix -> angles, such as 3DDFA_V2's ``matrix2angle``) reveals
  the same, plus which of the two Euler solutions it returns (``selection``);
- angles with 3-D landmarks give a physical rotation in a known frame, so there
  the comparison goes through ``to_canonical`` and the result is a complete
  system (see :mod:`hpe_cli.geometry.template`).

The candidate space
-------------------
The search runs over every product ``R_a(s1 t1) @ R_b(s2 t2) @ R_c(s3 t3)``:
3! assignments of the roles to the three positions, 12 axis sequences (6
Tait-Bryan, 6 proper Euler), 2^3 hands (``s = +1`` right-handed, ``-1``
left-handed), angles ``t`` in degrees: 576 functions. The other switches of a
rotation system add no new function:

- *extrinsic*: extrinsic a-b-c with angles (t1, t2, t3) is intrinsic c-b-a with
  (t3, t2, t1), so the 576 extrinsic products are the same 576 functions;
- *transpose*: ``(R1 R2 R3).T = R3(-t3) R2(-t2) R1(-t1)``, again in the set;
- *a built-in frame*: every built-in frame is a signed permutation, and
  ``B.T @ R_axis(t) @ B`` is a turn about another coordinate axis, hand flipped
  or not, so conjugated products stay in the set too.

So the ``3! x 2^3 x 12 x 2 x 2`` combinations (times the built-in frames)
collapse to 576 distinct
functions (any two differ at almost every generic sample), and each is
evaluated once. All of them are built in one batched ``matmul`` of shape
``(576, N, 3, 3)``; with N = 64 that takes a few milliseconds.

Matching and ranking
--------------------
A builder matches a candidate when the Frobenius error between the code's
matrix and the candidate's is within ``tol`` on *every* sample (64 well-spread
angle triples over the full circle). A decoder is called on uniformly random
rotations ``R``; a candidate explains a sample when its matrix of the decoded
angles rebuilds ``R`` within ``tol``. Decoders often special-case the gimbal
lock (3DDFA_V2 forces roll to 0 when ``|R[2,0]| > 0.998``), so a sample the
candidate does not explain is excused when it lies in the candidate's own lock
zone (``|cos b|`` or ``|sin b|`` of the middle turn below :data:`LOCK_ZONE`,
within ~5.7 deg of the lock, about 0.5 % of random rotations). A candidate is
an exact fit when no sample is left unexplained and at least
:data:`MIN_EXPLAINED` of them are explained. A decoder that is wrong outside
the lock zones (SynergyNet's ``matrix2angle_corr``) is therefore rejected.
Tables of angles with matrices use the decoder rule (dataset labels are often
the output of a decoder), and their selection is read the same way.

Candidates are ranked by the number of unexplained samples, then by the median
error. Several built-ins may share one function (``300w_lp`` and ``whenet``
differ only in the solution they keep); ties are broken by the decoder's
observed selection, then by the argument order and units matching the
system's storage order and units, then by a fixed priority.

Where it breaks
---------------
When nothing fits, the best partial fit is probed on structured inputs: for
each non-empty subset of the roles, random angles (10-60 deg, either sign) in
those roles and zero elsewhere. The report lists the subsets on which the code
agrees with the candidate and those on which it does not, with the largest
error and, for decoders, which output angles are wrong.

Landmarks
---------
With 3-D landmarks there is no exact answer: a template fitted to each face
gives an observed active rotation ``R_n`` in the canonical frame, with a degree
or two of noise. Each candidate ``g`` (now read as labels -> canonical matrix)
is scored by the geodesic residuals ``angle(g(labels_n) @ Q, R_n)``, where the
single rotation ``Q`` absorbs the template's own small tilt in the head frame
(fitted per candidate in closed form, so no candidate is favoured, and only
kept when under :data:`MAX_TEMPLATE_OFFSET_DEG`). The ranking uses the RMS
residual: orders of the same turns agree on small angles, and only the faces
with two large angles tell them apart, so a median would hide exactly the
decisive faces. The verdict is ``clear`` when the runner-up's RMS residual is
:data:`CLEAR_SEPARATION` times the winner's, ``poor`` when the winner's exceeds
:data:`POOR_RESIDUAL_DEG` or the template does not fit the landmarks, else
``ambiguous``. Built-in names come from each built-in's own
``to_canonical(from_angles(.))``; the report also lists each built-in's stored
matrix read directly as the canonical rotation (6DRepNet's ``get_R`` read that
way is the transpose of 300W-LP's matrix).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from .distances import angle_diff_deg, frobenius, geodesic_deg
from .elemental import axis_rotation
from .euler import lock_distance
from .systems import ROLES, RotationSystem, Turn, builtin_systems

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
_ROLE = {r: n for n, r in enumerate(ROLES)}


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

    def transpose(self) -> "Candidate":
        flip = {"right": "left", "left": "right"}
        return Candidate(self.roles[::-1], self.axes[::-1], tuple(flip[h] for h in self.hands[::-1]))

    def formula(self) -> str:
        """E.g. ``R = Rz(roll) @ Ry(-yaw) @ Rx(pitch)`` (a left-handed turn is a negated angle)."""
        return "R = " + " @ ".join(f"R{a}({'-' if h == 'left' else ''}{r})"
                                   for r, a, h in zip(self.roles, self.axes, self.hands))

    def words(self) -> str:
        def seq(turns):
            return ", then ".join(f"{t.angle} about {t.axis} ({t.hand}-handed)" for t in turns)

        return (f"intrinsic {'-'.join(self.axes.upper())}: {seq(self.turns)}; equivalently extrinsic "
                f"{'-'.join(self.axes[::-1].upper())}: {seq(self.turns[::-1])}")

    def default_selection(self) -> str:
        return "proper" if self.proper else "tait_bryan"

    def system(self, name: str = "custom", description: str = "", *, order=ROLES, units: str = "degrees",
               selection: str | None = None, frame=None, storage: str = "active", notes: str = "") -> RotationSystem:
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
        return RotationSystem(name=name, description=description or self.formula(), frame=frame, turns=self.turns,
                              sequence="intrinsic", storage=storage, order=tuple(order), units=units, ranges=ranges,
                              selection=selection, notes=notes)


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
    return np.array([[[_ROLE[r], _AXIS[a], int(h == "left")] for r, a, h in zip(c.roles, c.axes, c.hands)]
                     for c in candidates()], dtype=np.intp)


@lru_cache(maxsize=1)
def _index() -> dict:
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
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


# --------------------------------------------------------------------------- scoring
@dataclass
class Scores:
    """Per-candidate errors on the samples and the ranking they give."""

    index: np.ndarray      # (C,) candidate indices scored
    err: np.ndarray        # (C, N) Frobenius error
    excused: np.ndarray    # (C, N) bool: unexplained but inside the lock zone
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


def _rank_builtins(names, order=None, units=None, selection=None) -> list:
    systems = builtin_systems()

    def key(n):
        s = systems[n]
        return (s.storage_kind != "angles" or s.angle_frame != "system",  # systems that store angles first
                selection is not None and s.selection != selection,
                order is not None and tuple(s.order) != tuple(order),
                units is not None and s.units != units,
                PRIORITY.index(n) if n in PRIORITY else len(PRIORITY), n)

    return sorted(names, key=key)


# --------------------------------------------------------------------------- code adapters
def _to_numpy(out) -> np.ndarray:
    if hasattr(out, "detach"):  # a torch tensor, without importing torch
        out = out.detach().cpu().numpy()
    if isinstance(out, (tuple, list)):
        out = [o.detach().cpu().numpy() if hasattr(o, "detach") else o for o in out]
    return np.asarray(out, dtype=np.float64)


class CallError(ValueError):
    """The user's callable raised or returned something unusable."""


def as_builder(func, roles=ROLES, units: str = "radians", packed: bool = False):
    """Wrap ``func(*angles) -> 3x3`` as ``build(pyr_deg (N, 3)) -> (N, 3, 3)``.

    ``roles`` names the role of each positional argument; ``units`` the units
    ``func`` expects; ``packed``: ``func`` takes one sequence of three angles.
    The first call tries one vectorised call (arrays in, ``(N, 3, 3)`` or
    ``(3, 3, N)`` out) and checks it against per-sample calls on two samples;
    otherwise every later call goes sample by sample.
    """
    cols = [_ROLE[r] for r in roles]
    conv = np.deg2rad if units == "radians" else (lambda a: a)

    def call(args):
        return func(np.stack(args)) if packed else func(*args)

    def per_sample(pyr):
        out = np.empty((len(pyr), 3, 3))
        for n, row in enumerate(pyr):
            args = [float(conv(row[c])) for c in cols]
            try:
                m = _to_numpy(func(np.array(args)) if packed else func(*args))
            except Exception as exc:
                raise CallError(f"raised {type(exc).__name__} on angles {tuple(round(a, 6) for a in args)}: "
                                f"{' '.join(str(exc).split())[:200]}") from None
            if m.size != 9:
                raise CallError(f"expected a 3x3 matrix, got shape {m.shape}")
            out[n] = m.reshape(3, 3)
        return out

    def vectorised(pyr):
        try:
            m = _to_numpy(call([conv(pyr[:, c]) for c in cols]))
        except Exception:
            return None
        n = len(pyr)
        if m.shape == (n, 3, 3):
            return m
        if m.shape == (3, 3, n):
            return np.moveaxis(m, -1, 0)
        return None

    def build(pyr_deg):
        return dispatch(np.asarray(pyr_deg, dtype=np.float64).reshape(-1, 3))

    dispatch = _prefer_vectorised(vectorised, per_sample, atol=1e-9, equal_nan=False)
    build.state = dispatch.state
    return build


def as_decoder(func, roles=ROLES, units: str = "radians"):
    """Wrap ``func(R 3x3) -> three angles`` as ``decode(R (N, 3, 3)) -> (N, 3)`` role order, degrees.

    ``roles`` names the role of each returned angle, in the order returned.
    """
    cols = [_ROLE[r] for r in roles]
    conv = np.rad2deg if units == "radians" else (lambda a: a)

    def reorder(vals):
        out = np.empty_like(vals)
        out[:, cols] = conv(vals)
        return out

    def per_sample(R):
        vals = np.empty((len(R), 3))
        for n, m in enumerate(R):
            try:
                v = _to_numpy(func(m.copy()))
            except Exception as exc:
                raise CallError(f"raised {type(exc).__name__} on matrix row {n}: "
                                f"{' '.join(str(exc).split())[:200]}") from None
            if v.size != 3:
                raise CallError(f"expected three angles, got shape {v.shape}")
            vals[n] = v.reshape(3)
        return reorder(vals)

    def vectorised(R):
        try:
            v = _to_numpy(func(R.copy()))
        except Exception:
            return None
        n = len(R)
        if v.shape == (3, n):
            v = v.T
        return reorder(v) if v.shape == (n, 3) else None

    def decode(R):
        return dispatch(np.asarray(R, dtype=np.float64).reshape(-1, 3, 3))

    dispatch = _prefer_vectorised(vectorised, per_sample, atol=1e-7, equal_nan=True)
    decode.state = dispatch.state
    return decode


def _prefer_vectorised(vectorised, per_sample, atol: float, equal_nan: bool):
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


# --------------------------------------------------------------------------- reports
def _entry(cand_index: int, sc: Scores, stored: dict, canonical: dict | None = None) -> dict:
    pos = sc.pos_of(cand_index)
    c = candidates()[cand_index]
    t_index = _index()[c.transpose().key()]
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
    idx = _index()[cand.key()]
    rows = []
    for roles, pyr in _probe_subsets():
        err = frobenius(build(pyr), candidate_matrices(pyr, idx)[0])
        rows.append({"nonzero": roles, "exact": bool(np.all(err <= tol)), "max_error": float(np.nanmax(err))})
    return {"candidate": cand.formula(), "summary": _breaks_summary(rows), "probes": rows}


def probe_decoder(decode, cand: Candidate, tol: float) -> dict:
    """Where a decoder departs from candidate ``cand``: rebuild error and which output angles are wrong."""
    idx = _index()[cand.key()]
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
        rows.append({"nonzero": roles, "exact": bool(np.all(err <= tol)), "max_error": float(np.nanmax(err)),
                     "wrong_angles": wrong})
    return {"candidate": cand.formula(), "summary": _breaks_summary(rows), "probes": rows}


def _selection_of(cand: Candidate, R, decoded, tol: float):
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


def _result(mode: str, sc: Scores, *, roles, units, source, tol, n, name, frame, storage,
            selection=None, selection_fraction=None) -> dict:
    """Assemble the common part of a builder/decoder/table report."""
    stored = builtin_names_by_candidate()
    best_pos = int(sc.order[0])
    best_idx = int(sc.index[best_pos])
    cand = candidates()[best_idx]
    exact = sc.exact(best_pos)
    n_exact = int(sum(sc.exact(int(p)) for p in sc.order[:8]))
    units_word = "radians" if units in ("rad", "radians") else "degrees"
    report = {
        "mode": mode, "source": source, "roles": list(roles), "units": units_word, "samples": int(n),
        "tolerance": tol, "candidates": len(candidates()),
        "fit": "exact" if exact else "none",
    }
    entry = _entry(best_idx, sc, stored)
    if not exact:
        report.update(best="none", max_error=entry["max_error"], best_partial=entry,
                      runners_up=_runners_up(sc, stored, best_pos))
        return report
    names = _rank_builtins(entry["builtins"], order=tuple(roles), units=units_word, selection=selection)
    if names:
        base = builtin_systems()[names[0]]
        note = f"inferred from {source}: matches built-in {base.name}"
        changes = {}
        if selection is not None and selection != base.selection:
            # the function is the built-in's, but the code keeps the other solution: say so and keep the code's rule
            changes = {"selection": selection, "ranges": cand.system(selection=selection).ranges}
            note += f", except that it keeps the {selection} solution (the built-in keeps {base.selection})"
            report["selection_differs"] = note
        system = replace(base, order=tuple(roles), units=units_word,
                         notes=(base.notes + " " if base.notes else "") + note, **changes)
        if system.definition() != base.definition():  # a built-in's name may only carry its own definition
            system = replace(system, name=name or f"{base.name}_as_inferred")
        best = base.name
    else:
        system = cand.system(name or "custom", f"inferred from {source}: {cand.formula()}", order=roles,
                             units=units_word, selection=selection, frame=frame, storage=storage,
                             notes="frame and storage are not observable from angles and matrices alone; "
                                   "set them to what the code means")
        best = "custom"
    report.update(best=best, max_error=entry["max_error"], matched=entry, definition=system.describe(),
                  system=system.to_dict(), runners_up=_runners_up(sc, stored, best_pos))
    report["reproduced_by"] = names
    if len(names) > 1:
        report["also_matches"] = {"names": names[1:], "note": "same matrix from the same angles; these differ only "
                                  "in what the code cannot reveal (frame, storage, solution rule, storage order)"}
    if n_exact > 1:
        report["ambiguous"] = f"{n_exact} distinct functions fit these samples exactly; sample more varied angles"
    if selection is not None:
        report["selection"] = {"rule": selection, "fraction": selection_fraction}
    report["_system"] = system
    return report


def infer_builder(build, *, roles=ROLES, units="radians", n: int = 64, tol: float = CODE_TOL, seed: int = 0,
                  source: str = "<callable>", name: str | None = None, frame=None, storage: str = "active") -> dict:
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
    _check_rotations(M, "returned")
    sc = score(frobenius(candidate_matrices(pyr), M[None]), tol)
    rep = _result("callable", sc, roles=roles, units=units, source=source, tol=tol, n=n, name=name,
                  frame=frame, storage=storage)
    if rep["fit"] != "exact":
        cand = candidates()[int(sc.index[sc.order[0]])]
        rep["best_partial"]["breaks"] = probe_builder(build, cand, tol)
    return rep


def infer_decoder(decode, *, roles=ROLES, units="radians", n: int = 256, tol: float = CODE_TOL, seed: int = 0,
                  source: str = "<callable>", name: str | None = None, frame=None, storage: str = "active",
                  rotations=None) -> dict:
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
        sel, frac = _selection_of(best, R, d, tol)
        if frac < MIN_EXPLAINED:
            sel = None
    rep = _result("decoder", sc, roles=roles, units=units, source=source, tol=tol, n=n, name=name, frame=frame,
                  storage=storage, selection=sel, selection_fraction=frac)
    if rep["fit"] == "exact":
        if sel is None:
            rep["selection"] = {"rule": "none", "fraction": frac,
                                "note": "the decoder's choice between the two solutions follows no known rule"}
        pos = sc.pos_of(_index()[best.key()])
        exc = np.flatnonzero(sc.excused[pos])
        if exc.size:
            rep["near_lock"] = {"count": int(exc.size), "max_error": float(sc.err[pos, exc].max()),
                                "note": "samples within ~5.7 deg of gimbal lock that the decoder handles its own way"}
    else:
        rep["best_partial"]["breaks"] = probe_decoder(decode, best, tol)
    return rep


def infer_table(pyr_deg, R, *, roles=ROLES, units="degrees", tol: float = DATA_TOL, source: str = "<table>",
                name: str | None = None, frame=None, storage: str = "active", seed: int = 0) -> dict:
    """Same search on a table of angles (role order, degrees) with their stored matrices.

    Rows in a candidate's lock zone may disagree (labels there are often
    decoded imprecisely). At most :data:`SEARCH_ROWS` rows enter the search;
    the leaders are then checked on every row.
    """
    from .check import rotation_mask

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
        err = np.concatenate([frobenius(candidate_matrices(pyr[a:a + 65536], lead), R[a:a + 65536][None])
                              for a in range(0, len(pyr), 65536)], axis=1)
        locks = np.concatenate([candidate_locks(R[a:a + 65536], lead) for a in range(0, len(pyr), 65536)], axis=1)
        sc = score(err, tol, locks=locks, index=lead)
    sel = frac = None
    if sc.exact(int(sc.order[0])):  # labels are usually a decoder's output: which solution do they keep?
        sel, frac = _selection_of(candidates()[int(sc.index[sc.order[0]])], R, pyr, tol)
        sel = sel if frac >= MIN_EXPLAINED else None
    rep = _result("table", sc, roles=roles, units=units, source=source, tol=tol, n=len(pyr), name=name,
                  frame=frame, storage=storage, selection=sel, selection_fraction=frac)
    rep["rows_skipped"] = {"non_finite": int((~finite).sum()), "not_a_rotation": int((finite & ~ok).sum())}
    if rep["fit"] != "exact":
        pos = int(sc.order[0])
        bad = np.flatnonzero(sc.unexplained[pos])
        worst = bad[np.argsort(-sc.err[pos, bad])][:10]
        rep["best_partial"]["worst_rows"] = [int(i) for i in np.flatnonzero(ok)[worst]]
    return rep


def _check_rotations(M, verb: str) -> None:
    from .check import rotation_reasons

    M = np.asarray(M)
    if M.ndim != 3 or M.shape[1:] != (3, 3):
        raise CallError(f"expected matrices of shape (N, 3, 3), got {M.shape}")
    reasons = rotation_reasons(M, tol=1e-4)
    bad = np.flatnonzero(reasons != "")
    if bad.size:
        raise CallError(f"{verb} {reasons[bad[0]]} on sample {bad[0]} ({bad.size} of {len(M)} samples)")


# --------------------------------------------------------------------------- landmarks
def polar_rotation(M) -> np.ndarray:
    """Nearest proper rotation to each ``(..., 3, 3)`` matrix (Frobenius sense)."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


#: at least this many faces before a constant template offset is fitted per hypothesis
MIN_FACES_FOR_OFFSET = 8
#: largest constant template offset allowed (degrees): the template is frontal up to a small tilt
MAX_TEMPLATE_OFFSET_DEG = 15.0
#: a landmark answer is clear when the runner-up's RMS residual is at least this many times the winner's
CLEAR_SEPARATION = 2.0
#: ... and the winner's RMS residual is at most this (degrees)
POOR_RESIDUAL_DEG = 10.0


def _rms(res):
    return np.sqrt(np.mean(np.square(res), axis=-1))


def _landmark_residuals(G, R_obs, fit_offset: bool):
    """Geodesic residuals (C, N) of ``G @ Q`` against ``R_obs``; Q (C, 3, 3) the per-candidate offset."""
    if fit_offset:
        Q = polar_rotation(np.einsum("cnji,njk->cik", G, R_obs))
        # only a small tilt of the template is plausible; a large offset would hide a wrong frame
        big = geodesic_deg(Q, np.eye(3)) > MAX_TEMPLATE_OFFSET_DEG
        Q[big] = np.eye(3)
    else:
        Q = np.broadcast_to(np.eye(3), (G.shape[0], 3, 3))
    return geodesic_deg(np.matmul(G, Q[:, None]), R_obs[None]), Q


def infer_landmarks(pyr_deg, R_obs, *, roles=ROLES, fit_offset: bool | None = None, source: str = "<table>",
                    row_ids=None, fit_rmse=None, fit_rmse_limit: float | None = None, seed: int = 0,
                    name: str | None = None) -> dict:
    """Rank systems by how well their matrices from the labels explain observed rotations.

    Parameters
    ----------
    pyr_deg : array_like (N, 3)
        Labels in role order, degrees.
    R_obs : array_like (N, 3, 3)
        Observed active rotations in the canonical frame (e.g. a 68-point
        template fitted to each face, :mod:`hpe_cli.geometry.template`).
    fit_offset : bool, optional
        Fit one constant rotation ``Q`` per hypothesis (``R_obs ~ G(labels) @ Q``:
        the template's own tilt in the head frame, 3 parameters for all
        faces), used only when it is within :data:`MAX_TEMPLATE_OFFSET_DEG`
        (a larger one, such as the 180 deg turn that lets a mirrored face
        pass, is not a tilt). Default: only with at least
        :data:`MIN_FACES_FOR_OFFSET` faces.
    row_ids, fit_rmse : optional per-row identifiers and template-fit residuals for the report.
    fit_rmse_limit : float, optional
        When the median of ``fit_rmse`` is above it, the landmarks do not look
        like the template (a wrong landmark frame mirrors the face) and the
        verdict is ``poor`` whatever the residuals.

    Returns
    -------
    dict
        ``best`` (a built-in name whose labels-to-canonical map wins, or
        ``custom``), ``fit`` (``clear``, ``ambiguous`` or ``poor``),
        ``ranking`` (distinct functions by RMS residual, best first),
        ``hypotheses`` (each built-in's reading of the labels, and its stored
        matrix read as the active canonical rotation, grouped by function),
        ``per_face`` residuals in degrees for the winner.
    """
    pyr = np.asarray(pyr_deg, dtype=np.float64).reshape(-1, 3)
    R_obs = np.asarray(R_obs, dtype=np.float64).reshape(-1, 3, 3)
    ok = np.isfinite(pyr).all(1) & np.isfinite(R_obs).all((1, 2))
    rows = np.flatnonzero(ok)
    pyr, R_obs = pyr[ok], R_obs[ok]
    n = len(pyr)
    if n == 0:
        raise ValueError("no row has finite angles and a fitted rotation")
    if fit_offset is None:
        fit_offset = n >= MIN_FACES_FOR_OFFSET
    sub = np.arange(n) if n <= SEARCH_ROWS else np.sort(np.random.default_rng(seed).choice(n, SEARCH_ROWS, False))
    res, _ = _landmark_residuals(candidate_matrices(pyr[sub]), R_obs[sub], fit_offset)
    canon = builtin_canonical_by_candidate()
    stored = builtin_names_by_candidate()
    lead = np.unique(np.concatenate([np.argsort(_rms(res))[:10], list(canon), list(stored)]))
    res, Q = _landmark_residuals(candidate_matrices(pyr, lead), R_obs, fit_offset)
    rms, med = _rms(res), np.median(res, axis=1)
    order = np.argsort(rms, kind="stable")

    def entry(k):
        ci = int(lead[k])
        c = candidates()[ci]
        off = float(np.rad2deg(2 * np.arctan2(np.linalg.norm(Q[k] - np.eye(3)), np.linalg.norm(Q[k] + np.eye(3)))))
        return {"formula": c.formula(), "turns": c.words(),
                "builtins": _rank_builtins(canon.get(ci, []), order=tuple(roles)),
                "stored_matrix_of": stored.get(ci, []),
                "rms_residual_deg": float(rms[k]), "median_residual_deg": float(med[k]),
                "max_residual_deg": float(res[k].max()), "template_offset_deg": off}

    ranking = [entry(k) for k in order[:8]]
    best_k = int(order[0])
    second = float(rms[order[1]]) if len(order) > 1 else np.inf
    ratio = second / max(float(rms[best_k]), 1e-12)
    fit = "poor" if rms[best_k] > POOR_RESIDUAL_DEG else ("clear" if ratio >= CLEAR_SEPARATION else "ambiguous")
    warning = None
    if fit_rmse is not None and fit_rmse_limit is not None:
        fr = float(np.nanmedian(np.asarray(fit_rmse, dtype=np.float64)[rows])) if n else np.nan
        if not fr <= fit_rmse_limit:
            fit = "poor"
            warning = (f"the template fits the landmarks poorly (median RMSE {fr:.2f}, expected at most "
                       f"{fit_rmse_limit:g}): check the landmark frame")
    best = ranking[0]["builtins"][0] if ranking[0]["builtins"] else "custom"
    # every built-in reading of the labels is one of the candidates already scored
    readings: dict = {}
    for ci, names in canon.items():
        readings.setdefault(ci, []).extend(names)
    for ci, names in stored.items():
        readings.setdefault(ci, []).extend(f"{n} (stored matrix read as active)" for n in names
                                           if n not in canon.get(ci, []))
    pos = {int(ci): k for k, ci in enumerate(lead)}
    hyps = sorted(({"readings": r, "formula": candidates()[ci].formula(), "rms_residual_deg": float(rms[pos[ci]]),
                    "median_residual_deg": float(med[pos[ci]]), "max_residual_deg": float(res[pos[ci]].max())}
                   for ci, r in readings.items()), key=lambda h: h["rms_residual_deg"])
    ids = list(range(len(ok))) if row_ids is None else list(row_ids)
    per_face = [{"row": int(i), "id": ids[i], "residual_deg": float(v),
                 **({"fit_rmse": float(fit_rmse[i])} if fit_rmse is not None else {})}
                for i, v in zip(rows, res[best_k])]
    rep = {"mode": "landmarks", "source": source, "roles": list(roles), "units": "degrees", "samples": n,
           "candidates": len(candidates()), "template_offset_fitted": bool(fit_offset),
           "fit": fit, "best": best, "separation": ratio, "rms_residual_deg": float(rms[best_k]),
           "median_residual_deg": float(med[best_k]),
           "matched": ranking[0], "ranking": ranking, "hypotheses": hyps, "per_face": per_face,
           "rows_skipped": int((~ok).sum())}
    if warning:
        rep["warning"] = warning
    c = candidates()[int(lead[best_k])]
    system = builtin_systems()[best] if best != "custom" else c.system(
        name or "custom", f"inferred from {source}: {c.formula()} (canonical frame, active)", order=roles)
    rep["definition"] = system.describe()
    rep["system"] = system.to_dict()
    rep["_system"] = system
    return rep


def report_json(report: dict) -> dict:
    """The report without its in-memory objects (ready for :func:`hpe_cli.io.write_json`)."""
    return {k: v for k, v in report.items() if not k.startswith("_")}


# --------------------------------------------------------------------------- decoders returning stored values
#: (kind, order or 6-D columns, number of values) searched for a decoder that returns no angles
STORAGE_FORMS = ([("rotvec", None, 3), ("quaternion", "wxyz", 4), ("quaternion", "xyzw", 4)]
                 + [("6d", (i, j), 6) for i in range(3) for j in range(3) if i != j]
                 + [("matrix", None, 9)])


def as_value_decoder(func):
    """Wrap ``func`` (3x3 matrix -> k numbers, per sample or batched) as ``(N, 3, 3) -> (N, k)``."""

    def per_sample(R):
        return np.stack([_to_numpy(func(m)).reshape(-1) for m in R])

    def vectorised(R):
        out = _to_numpy(func(R))
        if out.ndim != 2 or out.shape[0] != len(R):
            raise ValueError("not batched")
        return out

    def decode(R):
        R = np.asarray(R, dtype=np.float64)
        try:
            return _prefer_vectorised(vectorised, per_sample, 1e-9, True)(R)
        except CallError:
            raise
        except Exception:  # noqa: BLE001 - the code may not take a batch
            return per_sample(R)

    return decode


def _form_matrices(kind, arg, values):
    from . import storage as st

    if kind == "rotvec":
        return st.rotvec_to_matrix(values)
    if kind == "quaternion":
        return st.quaternion_to_matrix(values, arg)
    if kind == "6d":
        return st.sixd_to_matrix(values, arg)
    return values.reshape(-1, 3, 3)


def _form_words(kind, arg, transposed):
    what = {"rotvec": "rotation vector (axis * angle, radians)",
            "quaternion": f"unit quaternion ({arg}, {'scalar first' if arg == 'wxyz' else 'scalar last'})",
            "6d": f"6-D: matrix column {arg[0] if arg else 0} then column {arg[1] if arg else 1}",
            "matrix": "3x3 matrix, row-major"}[kind]
    return f"{what} of the {'transpose of the ' if transposed else ''}matrix it is given"


def infer_storage_decoder(decode, *, n: int = 256, tol: float = CODE_TOL, seed: int = 0, source: str = "<callable>",
                          name: str | None = None, frame=None, **_ignored) -> dict:
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
    report = {"mode": "storage_decoder", "source": source, "samples": int(len(R)), "tolerance": tol,
              "values_per_sample": int(k), "candidates": len(tried)}
    if not tried:
        report.update(fit="none", best="none", max_error=float("inf"),
                      best_partial={"formula": f"no storage form returns {k} numbers (rotvec 3, quaternion 4, "
                                               "6-D 6, matrix 9)", "builtins": [], "explained": 0,
                                    "median_error": float("inf")}, runners_up=[])
        return report
    tried.sort(key=lambda t: (t[0], -t[2]))
    best = tried[0]
    entry = lambda t: {"formula": _form_words(t[3], t[4], t[5]), "max_error": t[0], "median_error": t[1],  # noqa
                       "explained": t[2], "builtins": [], "turns": f"storage_kind {t[3]}", "transpose_of": []}
    if best[0] > tol:
        report.update(fit="none", best="none", max_error=best[0], best_partial=entry(best),
                      runners_up=[entry(t) for t in tried[1:4]])
        return report
    kind, arg, transposed = best[3], best[4], best[5]
    same = [n_ for n_, s in builtin_systems().items() if s.storage_kind == kind and
            (kind != "quaternion" or s.quaternion_order == arg) and (kind != "6d" or tuple(s.sixd_columns) == arg)]
    d = {"name": name or "custom", "description": f"inferred from {source}: {_form_words(kind, arg, transposed)}",
         "storage_kind": kind, "storage": "transposed" if transposed else "active",
         "notes": "frame is not observable from code alone; set it to what the code means"}
    if frame is not None:
        d["frame"] = [list(map(float, r)) for r in frame]
    if kind == "quaternion":
        d["quaternion_order"] = arg
    if kind == "6d":
        d["sixd_columns"] = list(arg)
    from .systems import system_from_dict

    system = system_from_dict(d, source)
    e = entry(best)
    e["builtins"] = same
    report.update(fit="exact", best=system.name, max_error=best[0], matched=e,
                  definition=system.describe(), system=system.to_dict(), runners_up=[entry(t) for t in tried[1:4]],
                  reproduced_by=same, storage_form={"kind": kind, "order": arg, "transposed": transposed})
    if same:
        report["also_matches"] = {"names": same, "note": "built-ins storing the same form (their frame and "
                                  "storage may differ: code cannot reveal them)"}
    report["_system"] = system
    return report
