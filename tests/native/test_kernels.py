"""The compiled column kernels (``_hpe_kernels``) give the bits of their numpy twins, and both those of a plain
Python reference written from the definitions (not from either implementation).

Each test runs the code path twice, with the kernels and with ``HPE_KERNELS=numpy``; where the module is not
built, the kernel half is skipped and the numpy twin is still checked against the reference.
"""

from __future__ import annotations

import os
import struct
import warnings

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hpe_cli.native import kernels

MASK = (1 << 64) - 1
built = kernels() is not None
needs_kernels = pytest.mark.skipif(not built, reason="_hpe_kernels not built (no C compiler at install)")


def both(monkeypatch, fn):
    """``fn()`` with the numpy twins, and with the kernels where built: ``[numpy result, kernel result?]``."""
    monkeypatch.setenv("HPE_KERNELS", "numpy")
    out = [fn()]
    monkeypatch.delenv("HPE_KERNELS")
    if built:
        out.append(fn())
    return out


def twin_and_kernel(fn):
    """``[fn() with HPE_KERNELS=numpy, fn() as the environment has it]`` without pytest's monkeypatch (which a
    Hypothesis test cannot use per example)."""
    old = os.environ.pop("HPE_KERNELS", None)
    try:
        os.environ["HPE_KERNELS"] = "numpy"
        twin = fn()
        del os.environ["HPE_KERNELS"]
        return [twin, fn()]
    finally:
        os.environ.pop("HPE_KERNELS", None)
        if old is not None:
            os.environ["HPE_KERNELS"] = old


def mix_ref(h: int) -> int:
    h ^= h >> 30
    h = (h * 0xBF58476D1CE4E5B9) & MASK
    h ^= h >> 27
    h = (h * 0x94D049BB133111EB) & MASK
    return h ^ (h >> 31)


def string_hash_ref(b: bytes) -> int:
    """``sum b[i] P**i`` mod 2**64, the length times 0x9E3779B97F4A7C15 xor-ed in, SplitMix64's finaliser."""
    h = sum(c * pow(0x100000001B3, i, 1 << 64) for i, c in enumerate(b)) & MASK
    return mix_ref(h ^ ((len(b) * 0x9E3779B97F4A7C15) & MASK))


def stem_ref(b: bytes) -> bytes:
    """The text after the last / or \\ and before the last . after it."""
    cut = max(b.rfind(b"/"), b.rfind(b"\\"))
    b = b[cut + 1 :]
    dot = b.rfind(b".")
    return b[:dot] if dot >= 0 else b


texts = st.lists(
    st.one_of(st.none(), st.binary(max_size=12), st.sampled_from([b"", b".", b"/", b"a/b.c", b"\\x.y.z", b"d/.e"])),
    max_size=40,
)


@settings(max_examples=150, deadline=None)
@given(values=texts, large=st.booleans(), start=st.integers(0, 3))
def test_string_hashes_equal_the_reference_both_ways(values, large, start):
    from hpe_cli.io.key_hash import string_hashes

    arr = pa.array(values, type=pa.large_binary() if large else pa.binary()).slice(min(start, len(values)))
    kept = values[min(start, len(values)) :]
    want_x = [0xD6E8FEB86659FD93 if v is None else string_hash_ref(v) for v in kept]
    want_s = [0xD6E8FEB86659FD93 if v is None else string_hash_ref(stem_ref(v)) for v in kept]
    mp = pytest.MonkeyPatch()
    try:
        for hx, hs in both(mp, lambda: string_hashes(arr)):
            assert hx.tolist() == want_x and hs.tolist() == want_s
        for hx, hs in both(mp, lambda: string_hashes(arr, stems=False)):
            assert hx.tolist() == want_x and hs is None
    finally:
        mp.undo()


def float_word_ref(x: float) -> int:
    if x != x:
        return 0x7FF8000000000000
    return struct.unpack("<Q", struct.pack("<d", x + 0.0))[0]


def row_hash_ref(words) -> int:
    h = 0x9E3779B97F4A7C15
    for w in words:
        h = ((h ^ w) * 0x9FB21C651E98DF25) & MASK
        h ^= h >> 32
    return mix_ref(h)


nan_payloads = [struct.unpack("<d", struct.pack("<Q", b))[0] for b in (0x7FF8000000000001, 0xFFF8000000000000)]
floats = st.one_of(st.floats(allow_nan=True), st.sampled_from([0.0, -0.0, *nan_payloads, 90.0, -180.0]))


@settings(max_examples=100, deadline=None)
@given(rows=st.lists(st.tuples(floats, floats, floats, st.integers(-(2**53), 2**53), st.text(max_size=6)), max_size=30))
def test_row_hashes_equal_the_reference_both_ways(rows):
    from hpe_cli.pipelines.audit.duplicates import key_hashes

    cols = [np.array([r[k] for r in rows], dtype=np.float64) for k in range(3)]
    batch = pa.RecordBatch.from_arrays(
        [pa.array([r[3] for r in rows], type=pa.int64()), pa.array([r[4] for r in rows], type=pa.string())],
        names=["id", "image"],
    )
    want = [
        row_hash_ref(
            [float_word_ref(r[0]), float_word_ref(r[1]), float_word_ref(r[2]), float_word_ref(float(r[3]))]
            + [string_hash_ref(r[4].encode())]
        )
        for r in rows
    ]
    mp = pytest.MonkeyPatch()
    try:
        for h in both(mp, lambda: key_hashes(cols, batch, ("id", "image"))):
            assert h.tolist() == want
    finally:
        mp.undo()


@needs_kernels
@settings(max_examples=100, deadline=None)
@given(values=st.lists(st.integers(0, MASK), max_size=200))
def test_split_top_bit_is_the_boolean_split(values):
    h = np.array(values, dtype=np.uint64)
    low, high = np.empty(len(h), dtype=np.uint64), np.empty(len(h), dtype=np.uint64)
    n_low = kernels().split_top_bit(h, low, high)
    assert low[:n_low].tolist() == [v for v in values if v < 2**63]
    assert high[: len(h) - n_low].tolist() == [v for v in values if v >= 2**63]


@needs_kernels
def test_kernels_refuse_wrong_sizes_with_a_message():
    k = kernels()
    with pytest.raises(ValueError, match="expected 16 bytes, got 8"):
        k.row_hash_add(np.zeros(2, np.uint64), np.zeros(1, np.float64), True)
    with pytest.raises(ValueError, match="offsets"):
        k.string_hashes(np.array([0, 5], np.int64), np.zeros(3, np.uint8), None, np.zeros(1, np.uint64), None)


def test_hpe_kernels_numpy_turns_them_off(monkeypatch):
    monkeypatch.setenv("HPE_KERNELS", "numpy")
    assert kernels() is None
    monkeypatch.delenv("HPE_KERNELS")
    assert (kernels() is not None) == built


def test_the_module_is_built_where_it_can_be():
    """CI installs with a C compiler: a silently skipped build would leave every test here on the numpy twins."""
    import importlib
    import shutil
    import sysconfig
    from pathlib import Path

    if (
        not (shutil.which("cc") or shutil.which("gcc"))
        or not (Path(sysconfig.get_paths()["include"]) / "Python.h").exists()
    ):
        pytest.skip("no C compiler or no Python headers: the optional build skips _hpe_kernels")
    importlib.import_module("_hpe_kernels")  # run `pip install .` or `python setup.py build_ext --inplace`


@settings(max_examples=200, deadline=None)
@given(
    values=st.lists(
        st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.floats(-10.0, 10.0), st.integers(-720, 720)),
        min_size=64,
        max_size=300,
    )
)
def test_sin_cos_gives_numpys_bits(values):
    from hpe_cli.native import sin_cos

    x = np.deg2rad(np.array(values, dtype=np.float64))
    s, c = sin_cos(x)
    assert np.array_equal(s.view(np.int64), np.sin(x).view(np.int64))
    assert np.array_equal(c.view(np.int64), np.cos(x).view(np.int64))
    s2, c2 = sin_cos(x.reshape(-1, 1)[::-1])  # any shape and stride
    assert np.array_equal(s2.ravel()[::-1], s) and np.array_equal(c2.ravel()[::-1], c)


def test_sin_cos_kernel_used_only_where_the_probe_agrees(monkeypatch):
    import hpe_cli.native as native

    if built:  # the kernel is used exactly where it gives numpy's bits on the probe (here: glibc's sincos does)
        x = native._probe_angles()
        s, c = np.empty_like(x), np.empty_like(x)
        kernels().sin_cos(x, s, c)
        with np.errstate(invalid="ignore"):
            agree = np.array_equal(s.view(np.int64), np.sin(x).view(np.int64)) and np.array_equal(
                c.view(np.int64), np.cos(x).view(np.int64)
            )
        assert (native._sin_cos_kernel() is not None) == agree
    monkeypatch.setitem(native._STATE, "sin_cos", False)  # as on a machine where numpy's SIMD sine differs
    assert native._sin_cos_kernel() is None
    x = np.linspace(-7, 7, 200)
    s, c = native.sin_cos(x)
    assert np.array_equal(s, np.sin(x)) and np.array_equal(c, np.cos(x))


def _rotations(rng, n):
    """Random rotations, and the hard rows: identical pairs, 180 degrees apart, a hair apart, gimbal lock."""
    from scipy.spatial.transform import Rotation

    R = Rotation.random(n, random_state=rng).as_matrix()
    G = Rotation.random(n, random_state=rng).as_matrix()
    G[: n // 8] = R[: n // 8]  # 0 degrees
    G[n // 8 : n // 4] = R[n // 8 : n // 4] @ np.diag([1.0, -1.0, -1.0])  # 180 degrees
    tiny = Rotation.from_rotvec(rng.standard_normal((n // 8, 3)) * 1e-9).as_matrix()
    G[n // 4 : 3 * n // 8] = R[n // 4 : 3 * n // 8] @ tiny
    R[3 * n // 8 : n // 2] = Rotation.from_euler("xyz", [[10.0, 90.0, 30.0]] * (n // 8), degrees=True).as_matrix()
    return R, G


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_core_errors_give_the_numpy_functions_bits(seed):
    from hpe_cli.metrics import rotation_errors as re_
    from hpe_cli.native import core_errors

    R, G = _rotations(np.random.default_rng(seed), 4096)
    P, Q = re_.as_nested(R), re_.as_nested(G)
    P[0][1] = 0.0  # a constant entry (a float), as products of elemental rotations have
    Q[2][2] = np.broadcast_to(np.float64(0.5), (4096,))  # and a broadcast one
    got = core_errors(P, Q)
    if got is None:
        pytest.skip("no kernels, or the C library's atan2 differs from numpy's here")
    for a, b in zip(got, (re_.geodesic_deg(P, Q), re_.maev_deg(P, Q), re_.frobenius(P, Q))):
        assert a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def test_core_errors_used_only_where_atan2_agrees(monkeypatch):
    import hpe_cli.native as native

    monkeypatch.setitem(native._STATE, "atan2", False)  # as on a machine where numpy's SIMD atan2 differs
    R, G = _rotations(np.random.default_rng(4), 256)
    assert native.core_errors(R.transpose(1, 2, 0).tolist(), G.transpose(1, 2, 0).tolist()) is None


def test_a_module_from_older_sources_counts_as_not_built(monkeypatch):
    import types

    import hpe_cli.native as native

    monkeypatch.setitem(native._STATE, "module", None)
    monkeypatch.delitem(native._STATE, "module")
    stale = types.ModuleType("_hpe_kernels")
    stale.string_hashes = lambda *a: None  # only some of the functions this version calls
    monkeypatch.setitem(__import__("sys").modules, "_hpe_kernels", stale)
    assert native.kernels() is None
    monkeypatch.delitem(native._STATE, "module")  # the real module again for the other tests


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _hard_matrices(rng, n):
    """Random rotations with the rows an Euler split finds hard: the identity, 180-degree turns about each axis,
    every sequence's gimbal lock (middle angle 0, +-90 and 180 degrees, and 1e-8 rad off), a NaN row, and rows
    off orthonormal (which SciPy projects first)."""
    from scipy.spatial.transform import Rotation

    R = Rotation.random(n, random_state=rng).as_matrix()
    hard = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    for seq in ("xyz", "XYZ", "zyx", "ZXZ", "zxz"):
        for mid in (0.0, 90.0, -90.0, 180.0, 89.9999995, 1e-6):
            hard.append(Rotation.from_euler(seq, [[33.0, mid, -71.0]], degrees=True).as_matrix()[0])
    k = len(hard)
    R[:k] = np.array(hard)
    R[k] = np.nan
    return R


@pytest.mark.parametrize("seq", ["XYZ", "xyz", "ZYX", "zyx", "ZXZ", "xzx", "YXY"])
@pytest.mark.parametrize("assume_valid", [True, False])
def test_euler_from_matrix_gives_the_numpy_twins_bits_and_scipys_angles(monkeypatch, seq, assume_valid):
    from scipy.spatial.transform import Rotation

    from hpe_cli.metrics import scipy_columns as sc

    R = _hard_matrices(np.random.default_rng(len(seq) + assume_valid), 2048)
    N = sc.nested(R)
    for degrees in (True, False):
        got = both(monkeypatch, lambda: sc.euler_from_matrix(N, seq, degrees, assume_valid))
        assert all(_same_bits(g, got[0]) for g in got)
    ok = np.isfinite(R).all(axis=(1, 2))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # SciPy warns at gimbal lock
        ref = Rotation.from_matrix(R[ok]).as_euler(seq, degrees=False)
    assert np.allclose(
        got[-1][ok], ref, atol=1e-12, rtol=0
    )  # the oracle: SciPy itself (its bits: scipy_columns' tests)
    if built:
        off = R.copy()
        off[5] *= 1.001  # one row SciPy would project first: the kernel declines, the twin runs (same numbers)
        with monkeypatch.context() as m:
            m.setenv("HPE_KERNELS", "numpy")
            twin = sc.euler_from_matrix(sc.nested(off), seq, True, assume_valid)
        assert _same_bits(sc.euler_from_matrix(sc.nested(off), seq, True, assume_valid), twin)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.tuples(*[st.one_of(st.floats(-720, 720), st.sampled_from([0.0, -0.0, 90.0, -90.0, 180.0, -180.0]))] * 3),
        min_size=64,
        max_size=200,
    )
)
def test_quats_and_matrices_from_euler_give_the_numpy_twins_bits(angles):
    from scipy.spatial.transform import Rotation

    from hpe_cli.metrics import peer_angles as pa
    from hpe_cli.metrics import scipy_columns as sc

    a = np.array(angles, dtype=np.float64)
    (q0, M0), (q1, M1) = twin_and_kernel(lambda: pa.opal23_quats_and_matrices(a))
    assert all(_same_bits(x, y) for x, y in zip(q0, q1))
    assert all(_same_bits(M0[i][j], M1[i][j]) for i in range(3) for j in range(3))
    two_steps = sc.quat_from_euler("XYZ", a * [1.0, -1.0, 1.0], degrees=True)  # the sign, then the degrees' product
    assert all(_same_bits(x, y) for x, y in zip(q1, two_steps))
    r = Rotation.from_euler("XYZ", a * [1.0, -1.0, 1.0], degrees=True)  # the oracle: SciPy itself
    assert np.allclose(np.stack(q1, -1), r.as_quat(canonical=False), atol=1e-15, rtol=0)
    assert np.allclose(pa.stack3(M1), r.as_matrix(), atol=1e-15, rtol=0)


def test_opentrack_errors_give_the_numpy_twins_bits(monkeypatch):
    from hpe_cli.metrics import peer_angles as pa

    rng = np.random.default_rng(7)
    a = rng.uniform(-np.pi, np.pi, (4096, 3))
    b = a + rng.standard_normal((4096, 3)) * 0.1
    b[:512] = a[:512]  # equal angles: the argument rounds past 1 on some rows (the peer's NaN)
    b[512:600] = a[512:600] + np.pi  # opposite ones
    b[600] = np.nan
    got = both(monkeypatch, lambda: pa.opentrack_errors(a, b))
    assert all(_same_bits(g[0], got[0][0]) and np.array_equal(g[1], got[0][1]) for g in got)
    e, peer_nan = got[-1]
    d = np.abs(np.angle(np.exp(1j * (a - b))))  # the oracle: the wrapped difference, from complex numbers
    assert np.allclose(e[601:], np.degrees(d[601:]), atol=1e-6) and peer_nan[:512].any()


def test_libm_kernels_used_only_where_each_function_agrees(monkeypatch):
    import hpe_cli.native as native
    from hpe_cli.metrics import scipy_columns as sc

    R = sc.nested(_hard_matrices(np.random.default_rng(3), 256))
    if built:  # each probe says whether the C library's function gives numpy's bits on its values
        for name, (twin, probe) in native._LIBM.items():
            args = probe()
            args = args if isinstance(args, tuple) else (args,)
            out = np.empty_like(args[0])
            kernels().libm(name, args[0], args[1] if len(args) > 1 else None, out)
            with np.errstate(invalid="ignore"):
                assert (native._libm_kernels(name) is not None) == _same_bits(out, twin(*args))
    monkeypatch.setitem(native._STATE, "hypot", False)  # as on a machine where numpy's SIMD hypot differs
    monkeypatch.setitem(native._STATE, "scipy euler_from_matrix", False)  # and the kernel not SciPy's either
    assert native.euler_from_matrix(R, sc._seq_axes("XYZ"), True, False) is None
    monkeypatch.setitem(native._STATE, "acos", False)
    assert native.wrapped_cos_errors(np.zeros((100, 3)), np.ones((100, 3))) is None
    monkeypatch.setitem(native._STATE, "sin_cos", False)
    monkeypatch.setitem(native._STATE, "scipy quat_matrix_from_euler", False)
    assert native.quat_matrix_from_euler(np.zeros((100, 3)), (1.0, 1.0, 1.0), (0, 1, 2), True) is None
    if built:
        with pytest.raises(ValueError, match="expected atan2"):
            kernels().libm("exp", np.zeros(3), None, np.zeros(3))


def test_scipy_kernels_give_scipys_own_bits(monkeypatch):
    """SciPy's Cython backend calls the C library row by row, as the kernels do: each SciPy kernel gives SciPy's
    own bits (not only its numpy twin's) on hard rotations and on angles over the whole range."""
    from scipy.spatial.transform import Rotation

    import hpe_cli.native as native
    from hpe_cli.metrics import scipy_columns as sc

    if not built:
        pytest.skip("_hpe_kernels not built")
    R = _hard_matrices(np.random.default_rng(11), 2048)
    R = R[np.isfinite(R).all(axis=(1, 2))]  # not the NaN row
    for seq in ("xyz", "XYZ", "ZXZ", "zyx"):
        got = native.euler_from_matrix(sc.nested(R), sc._seq_axes(seq), False, False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # SciPy warns at gimbal lock
            assert _same_bits(got, Rotation.from_matrix(R).as_euler(seq)), seq
    a = np.random.default_rng(12).uniform(-7.0, 7.0, (2048, 3))
    a[:8] = [[0.0, np.pi / 2, 0.0], [np.pi, 0.0, -np.pi], [-0.0, 0.0, 0.0], [1e-300, -1e-9, 3.0]] * 2
    for seq in ("xyz", "ZXZ", "YXZ"):
        q, M = native.quat_matrix_from_euler(a, (1.0, 1.0, 1.0), [sc._AXIS[c] for c in seq.lower()], seq.isupper())
        r = Rotation.from_euler(seq, a)
        assert _same_bits(np.stack(q, -1), r.as_quat()) and _same_bits(np.array(M).transpose(2, 0, 1), r.as_matrix())


def test_scipy_probe_sequences_are_read_as_scipy_columns_reads_them():
    """The probe's two sequences are spelled out in hpe_cli.native (below the metrics layer): as _seq_axes reads them."""
    import hpe_cli.native as native
    from hpe_cli.metrics import scipy_columns as sc

    assert all(native._SCIPY_SEQS[seq] == sc._seq_axes(seq) for seq in native._SCIPY_SEQS)


def test_scipy_kernels_run_where_numpys_functions_are_not_the_c_librarys(monkeypatch):
    """On a CPU where numpy calls its own SIMD functions (Intel's SVML on AVX512_SKX), the numpy twins cannot give
    SciPy's bits; the SciPy kernels are then checked against SciPy itself and still used, the others not."""
    from scipy.spatial.transform import Rotation

    import hpe_cli.native as native
    from hpe_cli.metrics import scipy_columns as sc

    if not built:
        pytest.skip("_hpe_kernels not built")
    for name in ("atan2", "hypot", "sin_cos"):
        monkeypatch.setitem(native._STATE, name, False)  # numpy's functions differ from the C library's
    for name in ("scipy euler_from_matrix", "scipy quat_matrix_from_euler"):
        monkeypatch.delitem(native._STATE, name, raising=False)  # probed afresh
    R = _hard_matrices(np.random.default_rng(13), 512)
    R = R[np.isfinite(R).all(axis=(1, 2))]
    got = native.euler_from_matrix(sc.nested(R), sc._seq_axes("XYZ"), False, False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert got is not None and _same_bits(got, Rotation.from_matrix(R).as_euler("XYZ"))
    assert native._STATE["scipy euler_from_matrix"] is True
    a = np.random.default_rng(14).uniform(-3.0, 3.0, (512, 3))
    q, _ = native.quat_matrix_from_euler(a, (1.0, 1.0, 1.0), (2, 0, 2), True)
    assert _same_bits(np.stack(q, -1), Rotation.from_euler("ZXZ", a).as_quat())
    assert native.core_errors(sc.nested(R), sc.nested(R)) is None  # hpe's own metrics: numpy's twin, numpy's bits
    assert native.system_angles(sc.nested(R), (0, 1, 2, False, 1), (1.0, 1.0, 1.0), (0, 1, 2), 1, 1e-6) is None

    def broken(k):
        raise RuntimeError("no SciPy here")

    monkeypatch.setitem(native._SCIPY, "euler_from_matrix", (lambda: None, broken))
    monkeypatch.delitem(native._STATE, "scipy euler_from_matrix")
    assert native.euler_from_matrix(sc.nested(R), sc._seq_axes("XYZ"), False, False) is None  # the twin, no error


def test_evaluate_is_the_same_bytes_with_the_scipy_kernels_alone(monkeypatch, tmp_path):
    """Where numpy's functions are not the C library's, only the SciPy kernels run and the numpy twins do the rest:
    on a CPU where both give the same bits (this one, when its probes agree) every protocol's report and rows are
    the same bytes as with every kernel."""
    import filecmp

    import hpe_cli.native as native
    from conftest import repo_module
    from hpe_cli.api import evaluate_files

    if not built or native._libm_kernels("atan2", "hypot", "acos", "asin", "sin") is None:
        pytest.skip("no kernels, or numpy's functions are not the C library's here")
    repo_module("benchmarks/evaluate.py").make_tables(3000, tmp_path, False)
    args = dict(pred_system="6drepnet", gt_system="300w_lp", overwrite=True)
    runs = []
    for mixed in (False, True):
        with monkeypatch.context() as m:
            if mixed:
                for name in ("atan2", "hypot", "acos", "asin", "sin", "sin_cos"):
                    m.setitem(native._STATE, name, False)
            out, rep = tmp_path / f"rows{mixed:d}.parquet", tmp_path / f"report{mixed:d}.json"
            evaluate_files(tmp_path / "pred.parquet", tmp_path / "gt.parquet", output=out, report=rep, **args)
            if mixed:
                assert native._STATE["scipy euler_from_matrix"] and native._STATE["scipy quat_matrix_from_euler"]
        runs.append((out, rep))
    assert filecmp.cmp(runs[0][0], runs[1][0], shallow=False) and filecmp.cmp(runs[0][1], runs[1][1], shallow=False)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(*[st.one_of(st.floats(-180, 180), st.sampled_from([0.0, -0.0, 180.0, -180.0, 90.0, np.nan]))] * 6),
        min_size=1,
        max_size=100,
    )
)
def test_opal23_mae_gives_the_numpy_twins_bits(rows):
    from hpe_cli.metrics import peer_angles as pa

    special = np.array([0.0, -0.0, 180.0, -180.0, 90.0, -90.0, 179.9, np.nan])  # and every pair of them: 64 rows
    grid = np.stack(np.meshgrid(special, special), -1).reshape(-1, 2)[:, [0, 0, 1, 1, 1, 0]]
    x = np.concatenate([np.array(rows, dtype=np.float64).reshape(-1, 6), grid])
    a, p = x[:, :3], x[:, 3:]
    twin, got = twin_and_kernel(lambda: pa.opal23_mae(None, None, ann_euler=a, pred_euler=p))
    assert _same_bits(got, twin)


@pytest.mark.parametrize("seed", [0, 1])
def test_opal23_geodesic_and_near_quaternions_give_the_numpy_twins_bits(monkeypatch, seed):
    from hpe_cli.metrics import peer_angles as pa

    R, G = _rotations(np.random.default_rng(seed), 4096)
    R[7] = np.nan
    geo = both(monkeypatch, lambda: pa.opal23_geodesic(G, R))
    near = both(monkeypatch, lambda: pa.opal23_near_quats(G, R))
    mask = both(monkeypatch, lambda: pa.opal23_near_mask(G, R))
    assert all(_same_bits(g, geo[0]) for g in geo)
    assert all(_same_bits(q, near[0][0]) and np.array_equal(m, near[0][1]) for q, m in near)
    assert all(np.array_equal(m, near[0][1]) for m in mask)
    d = np.degrees(np.arccos(np.clip((np.einsum("nij,nij->n", G, R) - 1) / 2, -1, 1)))  # the oracle: the formula
    assert np.allclose(geo[-1], d, atol=1e-5, equal_nan=True)  # acos near 0 degrees: ~1e-6 degrees of rounding
    assert np.array_equal(near[-1][1], np.nan_to_num(d, nan=180.0) < 90.0)


def test_karcher_mean_gives_the_numpy_twins_bits(monkeypatch):
    from scipy.spatial.transform import Rotation

    from hpe_cli.metrics import peer_angles as pa

    rng = np.random.default_rng(11)
    base = Rotation.from_euler("xyz", [5.0, -8.0, 3.0], degrees=True)
    deltas = (base * Rotation.from_rotvec(rng.standard_normal((5000, 3)) * 0.2)).as_matrix()
    deltas[:40] = base.as_matrix()  # rotation vectors of 0 (the Taylor branch) after the first step
    q, near = pa.opal23_near_quats(np.broadcast_to(np.eye(3), deltas.shape), deltas)
    means = both(monkeypatch, lambda: pa.opal23_karcher(q, chunk=1 << 11))
    assert all(_same_bits(m, means[0]) for m in means)
    ref = Rotation.from_matrix(deltas[near]).mean().as_matrix()  # the oracle: SciPy's (chordal) mean, close by
    assert np.allclose(means[-1], ref, atol=1e-3)


def test_system_angles_give_the_numpy_twins_bits_in_every_system(monkeypatch):
    from scipy.spatial.transform import Rotation

    from hpe_cli.rotation.systems import get_system, system_names

    rng = np.random.default_rng(5)
    mid = 90 - 10.0 ** rng.uniform(-9, 1, 200)  # up to 10 degrees from the lock: refined rows and plain ones
    near = Rotation.from_euler(
        "zyx", np.c_[rng.uniform(-180, 180, 200), mid, rng.uniform(-180, 180, 200)], degrees=True
    )
    R = np.concatenate([_hard_matrices(rng, 3000), near.as_matrix(), near.as_matrix().transpose(0, 2, 1)])
    for name in system_names():
        system = get_system(name)
        X = system.soa_from_canonical([[R[:, i, j] for j in range(3)] for i in range(3)])
        got = both(monkeypatch, lambda: system.soa_to_angles(X))
        for g in got:
            assert all(_same_bits(a, b) for a, b in zip(g[0] + g[1] + [g[3]], got[0][0] + got[0][1] + [got[0][3]]))
            assert np.array_equal(g[2], got[0][2])


def repeated_ref(values) -> list:
    """The values occurring more than once, once each, in increasing order (a Counter of Python ints)."""
    from collections import Counter

    return sorted(v for v, c in Counter(int(v) for v in values).items() if c > 1)


@settings(max_examples=200, deadline=None)
@given(
    values=st.lists(
        st.one_of(st.integers(0, MASK), st.sampled_from([0, 1, 2**63 - 1, 2**63, MASK]), st.integers(0, 40)),
        max_size=300,
    )
)
def test_repeated_values_are_a_counters_both_ways(values):
    from hpe_cli.pipelines.audit.duplicates import repeated_in_place

    mp = pytest.MonkeyPatch()
    try:
        for got in both(mp, lambda: repeated_in_place(np.array(values, dtype=np.uint64)).tolist()):
            assert got == repeated_ref(values)
    finally:
        mp.undo()


def _large(kind: str, rng) -> np.ndarray:
    """Arrays past the kernel's leaf size, so it partitions (once or at every digit, down to equal values)."""
    n = 70_000
    if kind == "distinct":
        return rng.integers(0, MASK, n, dtype=np.uint64, endpoint=True)
    if kind == "pairs":  # every value twice or more, shuffled
        v = rng.integers(0, MASK, n // 2, dtype=np.uint64, endpoint=True)
        a = np.concatenate([v, v, v[:500]])
        rng.shuffle(a)
        return a
    if kind == "equal":  # one value: every digit partitions them into one bucket
        return np.full(n, 0x8000_0000_0000_0001, dtype=np.uint64)
    if kind == "shared_top_bits":  # top 40 bits shared: buckets too big for a leaf at several levels
        return (np.uint64(0xABCDEF1234) << np.uint64(24)) | rng.integers(0, 1 << 18, n).astype(np.uint64)
    if kind == "small_ints":  # 0 among them (an empty slot's mark in the kernel's hash sets)
        return rng.integers(0, 1000, n).astype(np.uint64)
    raise ValueError(kind)


@pytest.mark.parametrize("kind", ["distinct", "pairs", "equal", "shared_top_bits", "small_ints"])
def test_repeated_values_of_large_arrays_both_ways(monkeypatch, kind):
    from hpe_cli.pipelines.audit.duplicates import repeated_in_place

    a = _large(kind, np.random.default_rng(len(kind)))
    want = repeated_ref(a.tolist())
    for got in both(monkeypatch, lambda: repeated_in_place(a.copy())):
        assert got.tolist() == want


@needs_kernels
@settings(max_examples=150, deadline=None)
@given(
    batches=st.lists(
        st.lists(st.one_of(st.integers(0, MASK), st.sampled_from([0, 5, 2**63, MASK])), max_size=60), max_size=5
    ),
    bits=st.integers(1, 4),
    cap=st.integers(1, 40),
)
def test_hash_buckets_give_a_counters_repeats_or_say_they_are_full(batches, bits, cap):
    k = kernels()
    arr, cursors = np.zeros(cap << bits, np.uint64), np.zeros(1 << bits, np.int64)
    ok = all([k.bucket_file(np.array(b, dtype=np.uint64), arr, cursors, cap) for b in batches])
    values = [v for b in batches for v in b]
    counts = [sum(1 for v in values if v >> (64 - bits) == b) for b in range(1 << bits)]
    assert cursors.tolist() == counts
    assert ok == (max(counts) <= cap)
    if ok:  # the two bucket ranges a thread each, as the audit splits them
        half = 1 << (bits - 1)
        got = [np.frombuffer(k.bucket_repeats(arr, cursors, cap, lo, lo + half), np.uint64) for lo in (0, half)]
        assert np.concatenate(got).tolist() == repeated_ref(values)


@needs_kernels
def test_hash_buckets_refuse_wrong_sizes_with_a_message():
    k = kernels()
    with pytest.raises(ValueError, match="cursors: expected 2\\*\\*k int64 values"):
        k.bucket_file(np.zeros(3, np.uint64), np.zeros(12, np.uint64), np.zeros(3, np.int64), 4)
    with pytest.raises(ValueError, match="arr: expected 128 bytes, got 96"):
        k.bucket_file(np.zeros(3, np.uint64), np.zeros(12, np.uint64), np.zeros(4, np.int64), 4)
    with pytest.raises(ValueError, match="expected 0 <= lo <= hi <= 4 buckets"):
        k.bucket_repeats(np.zeros(16, np.uint64), np.zeros(4, np.int64), 4, 0, 5)


@needs_kernels
@pytest.mark.parametrize("kind", ["distinct", "pairs", "shared_top_bits", "small_ints"])
def test_hash_buckets_larger_than_a_leaf(kind):
    """Buckets of 35,000 values (a 30M-row audit has about 29,000 a bucket): partitioned again before the hash sets."""
    k = kernels()
    values = _large(kind, np.random.default_rng(7))
    cap = len(values)  # room for every value in either bucket
    arr, cursors = np.zeros(2 * cap, np.uint64), np.zeros(2, np.int64)
    for lo in range(0, len(values), 65536):
        assert k.bucket_file(values[lo : lo + 65536], arr, cursors, cap)
    assert cursors.sum() == len(values) and cursors.max() > 16384
    got = [np.frombuffer(k.bucket_repeats(arr, cursors, cap, b, b + 1), np.uint64) for b in (0, 1)]
    assert np.concatenate(got).tolist() == repeated_ref(values.tolist())


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(
            *[st.one_of(st.floats(-720, 720), st.sampled_from([0.0, -0.0, 180.0, -180.0, 360.0, 1e300, np.nan]))] * 9
        ),
        min_size=1,
        max_size=100,
    )
)
def test_best_of_two_and_wrapped_errors_give_the_numpy_twins_bits(rows):
    from hpe_cli.metrics import rotation_errors as re_

    x = np.concatenate([np.array(rows, dtype=np.float64).reshape(-1, 9), np.zeros((64, 9))])
    x[-64:] = np.random.default_rng(len(rows)).uniform(-200, 200, (64, 9))
    p1, p2, g = x[:, :3], x[:, 3:6], x[:, 6:]
    twin, got = twin_and_kernel(lambda: re_.best_and_wrapped(p1, p2, g))
    assert _same_bits(got[0], twin[0]) and np.array_equal(got[1], twin[1]) and _same_bits(got[2], twin[2])
    with np.errstate(invalid="ignore"):  # the oracle: the definitions, row by row in Python
        for i in range(0, len(x), 7):
            e1, e2 = np.abs(p1[i] - g[i]), np.abs(p2[i] - g[i])
            use = e2 if e2.mean() < e1.mean() else e1
            assert np.allclose(got[0][i], np.minimum(use, 360 - use), equal_nan=True, rtol=0, atol=1e-9)
            w = np.abs(p1[i] - g[i]) % 360
            assert np.allclose(got[2][i], np.minimum(w, 360 - w), equal_nan=True, rtol=0, atol=1e-9)


@pytest.mark.parametrize("middle", [0, 1, 2])
@pytest.mark.parametrize("proper", [False, True])
def test_second_solution_gives_the_numpy_twins_bits(middle, proper):
    from hpe_cli.rotation.solutions import second_degrees

    rng = np.random.default_rng(middle + 3 * proper)
    p1 = [rng.uniform(-180, 180, 500) for _ in range(3)]
    for c in p1:
        c[:12] = [0.0, -0.0, 180.0, -180.0, 1e-300, -1e-300, 5e-324, -5e-324, 90.0, -90.0, np.nan, 179.99999999999997]
    twin, got = twin_and_kernel(lambda: second_degrees(p1, middle, proper))
    assert all(_same_bits(a, b) for a, b in zip(got, twin))
    assert all(((c > -180) & (c <= 180)).sum() == len(c) - 1 for c in got)  # every angle in (-180, 180], NaN aside
