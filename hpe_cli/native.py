"""hpe's optional compiled column kernels (``_hpe_kernels``, ``csrc/kernels/``), or None.

Each kernel is one C loop over a column where numpy takes a dozen passes or more:

- hashes: the key hashes of ``hpe evaluate``'s join and duplicate-key check
  (:func:`hpe_cli.io.key_hash.string_hashes`), the row hashes of ``hpe audit``'s duplicate check and their split
  by value half (:func:`hpe_cli.pipelines.audit.duplicates.key_hashes`,
  :meth:`~hpe_cli.pipelines.audit.duplicates.Duplicates.file`), and the audit's repeated hashes found bucket by
  bucket instead of by a sort (``repeated_values``, ``bucket_file``, ``bucket_repeats``, called from
  :mod:`hpe_cli.pipelines.audit.duplicates`);
- the audit's angle screen;
- rotations: the sine and cosine of the matrices built from angles (:func:`sin_cos`), a rotation system's two Euler
  solutions (:func:`system_angles`, :func:`second_solution`), SciPy's Euler split of a matrix (:func:`euler_from_matrix`) and its
  ``from_euler`` quaternions with their matrices (:func:`quat_matrix_from_euler`);
- evaluate's error formulas: the core metrics (:func:`core_errors`, :func:`best_of_two`), opentrack's wrapped cosines
  (:func:`wrapped_cos_errors`), opal23's ``compute_mae`` and ``compute_ge`` (:func:`opal23_mae`,
  :func:`trace_acos_deg`), the near quaternions and the Karcher step of opal23's alignment (:func:`near_quats`,
  :func:`quat_rotvecs`);
- evaluate's key join: a chunk's rows put in partition order (:func:`partition_rows`, :func:`partition_strings`),
  a partition's rows paired by their key hashes (:func:`hash_pairs`) and verified on the key bytes
  (:func:`first_unequal`).

The hashes, the screen and the join compute integers and comparisons only, so each gives the bits of its numpy
twin; the others add IEEE arithmetic in numpy's order and call the C library's ``sincos``, ``atan2``, ``hypot``, ``acos``,
``asin`` or ``sin``, each only where that function gives numpy's bits on a probe of values (checked once a
process; the two that repeat SciPy's ``Rotation``, where numpy's functions are not the C library's, only where
they give SciPy's own bits: :func:`_scipy_kernels`). The numpy twins run where the module was not built (no C
compiler at install time) or when ``HPE_KERNELS=numpy`` is set; ``tests/native/`` compares the two.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

_STATE: dict = {}

#: the functions this version calls: a module that lacks one is treated as not built
KERNELS = (
    "string_hashes",
    "row_hash_add",
    "mix",
    "split_top_bit",
    "angle_screen",
    "sin_cos",
    "core_errors",
    "euler_from_matrix",
    "quat_matrix_from_euler",
    "wrapped_cos_errors",
    "opal23_mae",
    "trace_acos_deg",
    "near_quats",
    "quat_rotvecs",
    "system_angles",
    "best_of_two",
    "second_solution",
    "libm",
    "repeated_values",
    "bucket_file",
    "bucket_repeats",
    "hash_pairs",
    "first_unequal",
    "partition_scatter",
    "partition_strings",
)


def kernels():
    """The ``_hpe_kernels`` module, or None when it is not built or ``HPE_KERNELS=numpy`` asks for the numpy twins
    (read on each call: tests switch it)."""
    if os.environ.get("HPE_KERNELS", "").strip().lower() == "numpy":
        return None
    if "module" not in _STATE:
        try:
            import _hpe_kernels
        except ImportError:
            _hpe_kernels = None
        if _hpe_kernels is not None and not all(hasattr(_hpe_kernels, f) for f in KERNELS):
            _hpe_kernels = None  # a build from older sources (a checkout's stale .so): the numpy twins run
        _STATE["module"] = _hpe_kernels
    return _STATE["module"]


#: below this many rows numpy's calls cost less than a kernel's buffer handling
_MIN_ROWS = 64


def _agreeing(name: str, compare):
    """The kernels, if the C library function ``name`` gives numpy's bits on its probe, else None. ``compare(k)``
    runs the probe and returns ``[(kernel result, reference result), ...]`` (the reference: numpy's, or SciPy's for
    :func:`_scipy_kernels`); it runs once a process."""
    k = kernels()
    if k is None:
        return None
    if name not in _STATE:
        with np.errstate(invalid="ignore"):
            _STATE[name] = all(np.array_equal(a.view(np.int64), b.view(np.int64)) for a, b in compare(k))
    return k if _STATE[name] else None


def _probe_angles():
    """Angles whose sine and cosine the kernel must give with numpy's bits before it is used: whole and half
    degrees (what labels hold), multiples of pi/4, random radians near and far from 0, tiny, huge and special
    values."""
    rng = np.random.default_rng(20261128)
    return np.concatenate(
        [
            np.deg2rad(np.arange(-720.0, 720.5, 0.5)),
            np.arange(-32, 33) * (np.pi / 4),
            rng.uniform(-7.0, 7.0, 4096),
            rng.uniform(-1e6, 1e6, 512),
            rng.standard_normal(256) * 1e-9,
            [0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e22, -1e22, 1e300, np.inf, -np.inf, np.nan],
        ]
    )


def _sin_cos_kernel():
    """The kernel, if it gives numpy's bits on :func:`_probe_angles` (checked once a process), else None."""

    def compare(k):
        x = _probe_angles()
        s, c = np.empty_like(x), np.empty_like(x)
        k.sin_cos(x, s, c)
        return [(s, np.sin(x)), (c, np.cos(x))]

    return _agreeing("sin_cos", compare)


def sin_cos(x):
    """``(np.sin(x), np.cos(x))`` of a float64 array, in one C library call per value where the kernel is built and
    gives numpy's bits on this machine (:func:`_sin_cos_kernel`), else numpy's two calls: the same arrays either
    way, new ones (about 0.7x the time of numpy's two calls)."""
    x = np.asarray(x, dtype=np.float64)
    k = _sin_cos_kernel() if x.ndim >= 1 and x.size >= _MIN_ROWS else None
    if k is None:
        return np.sin(x), np.cos(x)
    x = np.ascontiguousarray(x)
    s, c = np.empty(x.shape), np.empty(x.shape)
    k.sin_cos(x.reshape(-1), s.reshape(-1), c.reshape(-1))
    return s, c


def _two_argument_probe():
    """``(y, x)`` pairs whose ``atan2`` and ``hypot`` the kernels must give with numpy's bits before they use them:
    every sign and quadrant, the axes, zeros of both signs, tiny, huge and special values, and the (sin, cos) pairs
    of whole and half degrees."""
    rng = np.random.default_rng(20261129)
    a = np.deg2rad(np.arange(-720.0, 720.5, 0.5))
    special = np.array([0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 1e-300, 1e300, -1e300, np.inf, -np.inf, np.nan])
    sy, sx = (g.ravel() for g in np.meshgrid(special, special))
    return (
        np.concatenate([np.sin(a), rng.standard_normal(4096) * 10.0 ** rng.uniform(-20, 20, 4096), sy]),
        np.concatenate([np.cos(a), rng.standard_normal(4096) * 10.0 ** rng.uniform(-20, 20, 4096), sx]),
    )


def _one_argument_probe():
    """Values whose ``acos`` and ``asin`` the kernels must give with numpy's bits: the cosines and sines of whole
    and half degrees, random values in [-1, 1] (dense near the ends), both zeros, the ends, just past them and
    special values."""
    rng = np.random.default_rng(20261130)
    a = np.deg2rad(np.arange(-180.0, 180.5, 0.5))
    u = rng.uniform(-1.0, 1.0, 4096)
    edge = 1.0 - 10.0 ** rng.uniform(-16, -1, 512)
    return np.concatenate(
        [np.cos(a), np.sin(a), u, edge, -edge, [0.0, -0.0, 1.0, -1.0, np.nextafter(1, 2), -np.nextafter(1, 2)]]
        + [[5e-324, 2.0, -2.0, np.inf, -np.inf, np.nan]]
    )


#: numpy's function of each C library function the kernels call, and the probe it is checked on
_LIBM = {
    "atan2": (np.arctan2, _two_argument_probe),
    "hypot": (np.hypot, _two_argument_probe),
    "acos": (np.arccos, _one_argument_probe),
    "asin": (np.arcsin, _one_argument_probe),
    "sin": (np.sin, _probe_angles),
}


def _libm_kernels(*names):
    """The kernels, if each of the C library's functions ``names`` (``atan2``, ``hypot``, ``acos``, ``asin``, ``sin``) gives
    numpy's bits on its probe (each checked once a process), else None."""

    def check(name):
        def compare(k):
            twin, probe = _LIBM[name]
            args = probe()
            args = args if isinstance(args, tuple) else (args,)
            out = np.empty_like(args[0])
            k.libm(name, args[0], args[1] if len(args) > 1 else None, out)
            return [(out, twin(*args))]

        return _agreeing(name, compare)

    k = None
    for name in names:
        k = check(name)
        if k is None:
            return None
    return k


def _probe_rotations() -> np.ndarray:
    """Rotations ``(N, 3, 3)`` on which the SciPy kernels must give SciPy's own bits: random ones, the identity,
    the half turns about each axis, and the gimbal locks of ``xyz`` and ``ZXZ`` (middle angle 0, +-90 and 180
    degrees, and just off 90)."""
    from scipy.spatial.transform import Rotation  # lazy: only where numpy's functions are not the C library's

    rng = np.random.default_rng(20261201)
    hard = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    for seq in _SCIPY_SEQS:
        for mid in (0.0, 90.0, -90.0, 180.0, 90.0 - 1e-6):
            hard.append(Rotation.from_euler(seq, [33.0, mid, -71.0], degrees=True).as_matrix())
    return np.concatenate([Rotation.random(1024, random_state=rng).as_matrix(), np.array(hard)])


#: two sequences SciPy's kernels are probed on, with their ``(i, j, k, sign, symmetric, intrinsic)`` as
#: hpe_cli.metrics.scipy_columns reads them (an extrinsic Tait-Bryan one and an intrinsic proper one)
_SCIPY_SEQS = {"xyz": (0, 1, 2, 1.0, False, False), "ZXZ": (2, 0, 1, 1.0, True, True)}


def _scipy_euler_probe(k):
    from scipy.spatial.transform import Rotation

    R = _probe_rotations()
    cols = [np.ascontiguousarray(R[:, r, c]) for r in range(3) for c in range(3)]
    pairs = []
    for seq, (i, j, m, sign, symmetric, intrinsic) in _SCIPY_SEQS.items():
        got = np.full((len(R), 3), np.nan)
        k.euler_from_matrix(cols, got, i, j, m, sign, symmetric, intrinsic, False, True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # SciPy warns at gimbal lock
            pairs.append((got, Rotation.from_matrix(R).as_euler(seq)))
    return pairs


def _scipy_from_euler_probe(k):
    from scipy.spatial.transform import Rotation

    a = _probe_angles()
    a = np.ascontiguousarray(np.resize(a[np.isfinite(a) & (np.abs(a) < 1e6)], (2048, 3)))
    pairs = []
    for seq in _SCIPY_SEQS:
        q, M = np.empty((4, len(a))), np.empty((9, len(a)))
        axes = tuple("xyz".index(c) for c in seq.lower())  # each turn's axis, in seq's order
        k.quat_matrix_from_euler(a, (1.0, 1.0, 1.0), axes, seq.isupper(), q, M)
        r = Rotation.from_euler(seq, a)
        pairs += [(q.T.copy(), r.as_quat()), (M.T.reshape(-1, 3, 3).copy(), r.as_matrix())]
    return pairs


#: each kernel that repeats SciPy's ``Rotation`` arithmetic: the C library functions whose agreement with numpy's
#: makes it the numpy twin's bits, and its probe against SciPy itself
_SCIPY = {
    "euler_from_matrix": (lambda: _libm_kernels("atan2", "hypot"), _scipy_euler_probe),
    "quat_matrix_from_euler": (lambda: _sin_cos_kernel(), _scipy_from_euler_probe),
}


def _scipy_kernels(name: str):
    """The kernels, if kernel ``name`` (one of :data:`_SCIPY`) gives SciPy's bits here, else None.

    SciPy's Cython backend, which NumPy arrays go through, calls the C library's ``atan2``, ``hypot``, ``sin`` and
    ``cos`` row by row, as the kernels do. Where numpy's functions are the C library's too (the probes of
    :data:`_LIBM`), the kernel, its numpy twin and SciPy give the same bits. Where they are not (numpy calls Intel's
    SVML on AVX512_SKX CPUs), the twin cannot give SciPy's bits and the kernel still can: it is checked against
    SciPy itself on :func:`_probe_rotations` or :func:`_probe_angles` (once a process) and used where it agrees.
    """
    same_as_numpy, probe = _SCIPY[name]
    k = same_as_numpy()
    if k is not None or kernels() is None:
        return k

    def compare(k):
        try:
            return probe(k)
        except Exception:  # noqa: BLE001 - a SciPy that cannot run the probe: the twin runs, never an error
            return [(np.zeros(1), np.ones(1))]

    return _agreeing(f"scipy {name}", compare)


def _columns(X, n: int) -> list:
    """The 9 entries of a nested 3x3 list (arrays or floats) as contiguous float64 columns of ``n`` rows."""
    return [np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=np.float64), (n,))) for row in X for v in row]


def _rows(X) -> int:
    return int(np.broadcast(*[x for row in X for x in row]).shape[0])


def _angle_rows(*arrays):
    """The arrays as contiguous float64 ``(N, 3)`` arrays of one shape, or None when they are not that or have
    fewer than :data:`_MIN_ROWS` rows (the kernels over angle triples take them so)."""
    out = [np.ascontiguousarray(x, dtype=np.float64) for x in arrays]
    a = out[0]
    ok = a.ndim == 2 and a.shape[1] == 3 and len(a) >= _MIN_ROWS and all(x.shape == a.shape for x in out)
    return out if ok else None


def euler_from_matrix(R, axes, degrees: bool, check: bool):
    """SciPy's ``Rotation.from_matrix(R).as_euler(seq)`` of a nested 3x3 list of columns in one C loop, or None
    (kernels not built, the kernel not giving SciPy's bits here (:func:`_scipy_kernels`), too few rows, or with
    ``check`` a row that SciPy would first project onto the rotations: then
    :func:`hpe_cli.metrics.scipy_columns.euler_from_matrix` computes them, the same numbers).

    ``axes`` is ``(i, j, k, sign, symmetric, intrinsic)`` as that function reads ``seq``. Returns ``(N, 3)``.
    """
    n = _rows(R)
    k = _scipy_kernels("euler_from_matrix") if n >= _MIN_ROWS else None
    if k is None:
        return None
    out = np.empty((n, 3))
    i, j, m, sign, symmetric, intrinsic = axes
    if k.euler_from_matrix(_columns(R, n), out, i, j, m, float(sign), symmetric, intrinsic, degrees, check):
        return None
    return out


def quat_matrix_from_euler(angles, scale, axes, intrinsic: bool):
    """SciPy's ``Rotation.from_euler(seq, angles * scale)``'s quaternions ``(x, y, z, w)`` and matrices (nested 3x3
    list of columns) in one C loop, or None (kernels not built, the kernel not giving SciPy's bits here
    (:func:`_scipy_kernels`), or too few rows: then :mod:`hpe_cli.metrics.scipy_columns` computes them, the same
    numbers).

    ``angles`` is ``(N, 3)``, ``scale`` the 3 factors each column is multiplied by first (one product: e.g. the
    degrees' ``pi / 180`` with a sign), ``axes`` the 3 axes (0, 1, 2 for x, y, z) in seq's order.
    """
    got = _angle_rows(angles)
    k = _scipy_kernels("quat_matrix_from_euler") if got is not None else None
    if k is None:
        return None
    a, n = got[0], len(got[0])
    q, M = np.empty((4, n)), np.empty((9, n))
    k.quat_matrix_from_euler(a, tuple(float(v) for v in scale), tuple(int(v) for v in axes), intrinsic, q, M)
    return tuple(q), [[M[3 * r + c] for c in range(3)] for r in range(3)]


def wrapped_cos_errors(e1, e2):
    """``(degrees(arccos(clip(cos a cos b + sin a sin b, -1, 1))) (N, 3), rows with an argument past +-1 (N,))``
    of two ``(N, 3)`` angle arrays (radians) in one C loop, or None (kernels not built, or the C library's
    ``sincos`` or ``acos`` not numpy's here: then :func:`hpe_cli.metrics.peer_angles.opentrack_errors` computes
    them, the same numbers)."""
    got = _angle_rows(e1, e2)
    if got is None or _sin_cos_kernel() is None or _libm_kernels("acos") is None:
        return None
    a, b = got
    out, nan = np.empty(a.shape), np.empty(len(a), dtype=bool)
    kernels().wrapped_cos_errors(a, b, out, nan.view(np.uint8))
    return out, nan


def core_errors(P, G):
    """``(geodesic (N,), column angles (N, 3), Frobenius distance (N,))`` of nested 3x3 lists of columns (arrays or
    floats) in one C loop, or None where the kernels are not built or the C library's ``atan2`` does not give
    numpy's bits (then :mod:`hpe_cli.metrics.rotation_errors` computes them: the same numbers)."""
    n = _rows([*P, *G])
    k = _libm_kernels("atan2") if n >= _MIN_ROWS else None
    if k is None:
        return None
    geo, maev, fro = np.empty(n), np.empty((n, 3)), np.empty(n)
    k.core_errors(_columns(P, n), _columns(G, n), geo, maev, fro)
    return geo, maev, fro


def opal23_mae(a, p):
    """opal23's ``compute_mae`` of two ``(N, 3)`` ``as_euler('XYZ')`` angle arrays (degrees) in one C loop, or None
    (kernels not built or too few rows: then :func:`hpe_cli.metrics.peer_angles.opal23_mae` computes it, the same
    numbers). No C library function is called: the bits are numpy's by construction."""
    got = _angle_rows(a, p)
    k = kernels() if got is not None else None
    if k is None:
        return None
    a, p = got
    out = np.empty(a.shape)
    k.opal23_mae(a, p, out)
    return out


def trace_acos_deg(A, P):
    """``degrees(arccos(clip((trace(A P^T) - 1) / 2, -1, 1)))`` of nested 3x3 lists of columns in one C loop, or None
    (kernels not built, the C library's ``acos`` not numpy's here, or too few rows: then
    :func:`hpe_cli.metrics.peer_angles.opal23_geodesic` computes it, the same numbers)."""
    n = _rows([*A, *P])
    k = _libm_kernels("acos") if n >= _MIN_ROWS else None
    if k is None:
        return None
    out = np.empty(n)
    k.trace_acos_deg(_columns(A, n), _columns(P, n), out)
    return out


def near_quats(P, A):
    """``(unit quaternions (N, 4) of P A^T (x, y, z, w), rows within 90 degrees of the identity (N,))`` of nested
    3x3 lists of columns in one C loop, or None (kernels not built, the C library's ``atan2`` not numpy's here, or
    too few rows: then :func:`hpe_cli.metrics.peer_angles.opal23_near_quats` computes them, the same numbers)."""
    n = _rows([*P, *A])
    k = _libm_kernels("atan2") if n >= _MIN_ROWS else None
    if k is None:
        return None
    q, near = np.empty((n, 4)), np.empty(n, dtype=bool)
    k.near_quats(_columns(P, n), _columns(A, n), q, near.view(np.uint8))
    return q, near


def quat_rotvecs(q, left):
    """SciPy's ``as_rotvec`` ``(m, 3)`` (radians) of ``left @ q`` for quaternion columns ``q`` (4 arrays of m rows:
    x, y, z, w) and a 4x4 ``left``, in one C loop, or None (kernels not built, the C library's ``atan2`` or ``sin``
    not numpy's here, or too few rows: then :mod:`hpe_cli.metrics.scipy_columns` computes them, the same
    numbers)."""
    m = len(q[0])
    k = _libm_kernels("atan2", "sin") if m >= _MIN_ROWS else None
    if k is None:
        return None
    out = np.empty((m, 3))
    k.quat_rotvecs([np.ascontiguousarray(c, dtype=np.float64) for c in q], np.ascontiguousarray(left, np.float64), out)
    return out


def system_angles(X, spec, scale, roles, middle: int, refine_below: float):
    """A rotation system's two Euler solutions of a nested 3x3 list of columns in one C loop, or None (kernels not
    built, the C library's ``atan2`` not numpy's here, or too few rows: then
    :meth:`hpe_cli.rotation.system_def.RotationSystem.soa_to_angles` computes them, the same numbers).

    ``spec`` is ``(i, j, k, proper, parity)`` of the intrinsic sequence (``k`` the plane's third axis when proper),
    ``scale`` each turn's degrees factor (its hand's sign), ``roles`` each turn's place in (pitch, yaw, roll),
    ``middle`` the middle turn's. Returns ``(p1 (3, N), p2 (3, N), lock (N,), near (N,))``: the rows of ``near``
    (lock below ``refine_below``) are the caller's to recompute.
    """
    n = _rows(X)
    k = _libm_kernels("atan2") if n >= _MIN_ROWS else None
    if k is None:
        return None
    p1, p2, lock, near = np.empty((3, n)), np.empty((3, n)), np.empty(n), np.empty(n, dtype=bool)
    i, j, m, proper, e = spec
    k.system_angles(
        _columns(X, n),
        p1,
        p2,
        lock,
        near.view(np.uint8),
        i,
        j,
        m,
        proper,
        float(e),
        tuple(scale),
        tuple(roles),
        middle,
        refine_below,
    )
    return p1, p2, lock, near


def hash_pairs(hg, hp):
    """``(rows of hg with a match, their rows in hp)``, the first ascending, of two uint64 arrays by equal values, in
    one cache-sized pass per bucket of the top bits; False when a value repeats on one side; None where the kernels
    are not built (then :func:`hpe_cli.pipelines.evaluate.spill.hash_matches` sorts: the same pairs)."""
    k = kernels()
    if k is None or len(hg) + len(hp) < _MIN_ROWS:
        return None
    pos = np.empty(len(hg), dtype=np.int64)
    if not k.hash_pairs(np.ascontiguousarray(hg, np.uint64), np.ascontiguousarray(hp, np.uint64), pos):
        return False
    gi = np.flatnonzero(pos >= 0)
    return gi, pos[gi]


def _string_buffers(arr):
    """``(offsets view, data, wide)`` of a pyarrow ``string``/``large_string`` array without nulls (its own offset
    applied): the buffers as they are, no copy."""
    wide = str(arr.type) in ("large_string", "large_utf8")
    width = 8 if wide else 4
    bufs = arr.buffers()
    off = np.frombuffer(bufs[1], dtype=np.uint8, count=(len(arr) + 1) * width, offset=arr.offset * width)
    data = bufs[2] if bufs[2] is not None else b""
    return off, data, wide


def first_unequal(a, rows_a, b, rows_b):
    """The first ``j`` where the strings ``a[rows_a[j]]`` (``a[j]`` when ``rows_a`` is None) and ``b[rows_b[j]]``
    differ, -1 when none does, in one C loop over the Arrow buffers (no gather); None where the kernels are not
    built or an array is not text without nulls (then the caller compares taken arrays with pyarrow: the same
    answer). ``a``, ``b``: pyarrow string or large_string arrays; rows: int64 arrays."""
    k = kernels()
    if k is None:
        return None
    text = ("string", "utf8", "large_string", "large_utf8")
    if str(a.type) not in text or str(b.type) not in text or a.null_count or b.null_count:
        return None
    oa, da, wa = _string_buffers(a)
    ob, db, wb = _string_buffers(b)
    ra = None if rows_a is None else np.ascontiguousarray(rows_a, np.int64)
    return k.first_unequal(oa, da, ra, ob, db, np.ascontiguousarray(rows_b, np.int64), wa, wb)


def partition_rows(part, K: int, arrays):
    """``(bounds int64[K+1], arrays with their rows in stable partition order)``: ``part`` (int16, each in
    ``[0, K)``) the partition of each row, ``arrays`` numpy arrays of ``len(part)`` rows (any fixed-width dtype, any
    trailing shape), in one C counting sort; None where the kernels are not built (then the caller takes
    ``np.argsort(part, kind="stable")``: the same rows)."""
    k = kernels()
    if k is None:
        return None
    part = np.ascontiguousarray(part, dtype=np.int16)
    n = len(part)
    srcs = tuple(np.ascontiguousarray(a) for a in arrays)
    dsts = tuple(np.empty_like(a) for a in srcs)
    widths = tuple(a.dtype.itemsize * (a.size // n if n else 1) for a in srcs)
    bounds = np.empty(K + 1, dtype=np.int64)
    k.partition_scatter(part, K, bounds, srcs, dsts, widths)
    return bounds, list(dsts)


def partition_strings(part, K: int, arr):
    """A pyarrow ``string``/``large_string`` array without nulls, its rows in the stable partition order of
    :func:`partition_rows`, in one C pass over its buffers; None where the kernels are not built or the array is not
    text without nulls (then the caller takes it with pyarrow: the same strings)."""
    import pyarrow as pa  # lazy: start-up (the kernels' other callers need none)

    k = kernels()
    if k is None or arr.null_count or str(arr.type) not in ("string", "utf8", "large_string", "large_utf8"):
        return None
    off, data, wide = _string_buffers(arr)
    width = np.int64 if wide else np.int32
    first, last = (int(x) for x in np.frombuffer(off, dtype=width)[[0, -1]])
    out_off = np.empty(len(arr) + 1, dtype=width)
    out_data = np.empty(last - first, dtype=np.uint8)
    k.partition_strings(np.ascontiguousarray(part, dtype=np.int16), K, off, data, out_off, out_data, wide)
    return pa.Array.from_buffers(arr.type, len(arr), [None, pa.py_buffer(out_off), pa.py_buffer(out_data)])


def best_of_two(p1, p2, g, wrapped: bool):
    """``(best (N, 3), second (N,), wrapped (N, 3) or None)``: hpe's best-of-two and wrapped angle errors of three
    ``(N, 3)`` angle arrays (degrees) in one C loop, or None (kernels not built or too few rows: then
    :mod:`hpe_cli.metrics.rotation_errors` computes them, the same numbers; no C library function but ``fmod``)."""
    got = _angle_rows(p1, p2, g)
    k = kernels() if got is not None else None
    if k is None:
        return None
    a, b, c = got
    best, second = np.empty(a.shape), np.empty(len(a), dtype=bool)
    w = np.empty(a.shape) if wrapped else None
    k.best_of_two(a, b, c, best, second.view(np.uint8), w)
    return best, second, w


def second_solution(p1, middle: int, proper: bool):
    """The other Euler solution ``(3, N)`` (degrees) of the primary angles ``p1`` (3 columns), in one C loop, or
    None (kernels not built or too few rows: then :func:`hpe_cli.rotation.solutions.second_degrees` computes it,
    the same numbers)."""
    cols = [np.asarray(c, dtype=np.float64) for c in p1]
    n = len(cols[0]) if cols and cols[0].ndim == 1 else 0
    k = kernels() if n >= _MIN_ROWS and all(c.shape == (n,) for c in cols) else None
    if k is None:
        return None
    out = np.empty((3, n))
    k.second_solution([np.ascontiguousarray(c) for c in cols], middle, proper, out)
    return out
