"""convert's column kernels work in blocks of rows (issue 33): the numbers do not depend on the blocking, the
batch size or the thread count, bit for bit, and they are the right ones (SciPy ``Rotation`` as the oracle).

Rows at and near gimbal lock (the refined and the split branches of the Euler extraction) and rows that go to
the rejects are in every table.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from conftest import hpe
from hpe_cli.rotation import get_system, soa, solutions, system_names
from hpe_cli.rotation.check import rotation_mask, rotation_screen_columns
from hpe_cli.rotation.convert import soa_labels

N = 2 * soa.BLOCK + 777  # three blocks, the last one partial


def _canonical(n, seed=3):
    """``n`` canonical matrices: random ones, and for every built-in system rows at and near its gimbal lock."""
    rng = np.random.default_rng(seed)
    w = get_system("300w_lp")
    pyr = np.c_[rng.uniform(-180, 180, n), rng.uniform(-90, 90, n), rng.uniform(-180, 180, n)]
    A = w.to_canonical(w.from_angles(pyr))
    k = 0
    for name in system_names():
        s = get_system(name)
        mid = solutions.middle_role(s)
        for v in (90.0, -90.0, 90 - 1e-9, 89.9999, 88.0):
            a = rng.uniform(-180, 180, (40, 3))
            a[:, mid] = v
            A[k : k + 40] = s.to_canonical(s.from_angles(a))
            k += 40
    return A[rng.permutation(n)]


def _bits(x):
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize("name", system_names())
def test_labels_do_not_depend_on_the_blocks(name):
    """Rows converted in one call, or split at places that are not block boundaries, give the same bits."""
    target = get_system(name)
    A = _canonical(N)
    whole = soa_labels(soa.from_array(A), target, N)
    cut = [0, 5, soa.BLOCK + 3, N - 100, N]
    for lo, hi in zip(cut, cut[1:]):
        part = soa_labels(soa.from_array(A[lo:hi]), target, hi - lo)
        for key in ("primary", "secondary"):
            for w, p in zip(whole[key], part[key]):
                assert np.array_equal(_bits(w[lo:hi]), _bits(p))
        assert np.array_equal(_bits(whole["roundtrip_err"][lo:hi]), _bits(part["roundtrip_err"]))
        assert np.array_equal(whole["gimbal_lock"][lo:hi], part["gimbal_lock"])


def test_labels_against_scipy():
    """scipy_zyx angles are SciPy's intrinsic ZYX (yaw, pitch, roll); both solutions rebuild the input matrix."""
    target = get_system("scipy_zyx")
    A = _canonical(N)
    lab = soa_labels(soa.from_array(A), target, N)
    R = soa.to_array(lab["matrix"], N)
    assert np.allclose(R, target.from_canonical(A), atol=0)
    away = ~lab["gimbal_lock"]
    yaw, pitch, roll = Rotation.from_matrix(R[away]).as_euler("ZYX", degrees=True).T
    gap = np.stack(lab["primary"], -1)[away] - np.c_[pitch, yaw, roll]
    assert np.abs((gap + 180.0) % 360.0 - 180.0).max() < 1e-9  # SciPy writes -180 where hpe writes 180
    for key in ("primary", "secondary"):
        p, y, r = lab[key]
        rebuilt = Rotation.from_euler("ZYX", np.c_[y, p, r], degrees=True).as_matrix()
        assert np.abs(rebuilt - R).max() < 1e-9
    # the round-trip error is the Frobenius distance between the input and the primary solution's rotation
    p, y, r = lab["primary"]
    rebuilt = target.to_canonical(Rotation.from_euler("ZYX", np.c_[y, p, r], degrees=True).as_matrix())
    np.testing.assert_allclose(lab["roundtrip_err"], np.sqrt(((A - rebuilt) ** 2).sum(axis=(1, 2))), atol=1e-14)
    assert lab["roundtrip_err"].max() < 1e-12


ANGLE = st.one_of(
    st.floats(-180, 180, allow_nan=False),
    st.sampled_from([-180.0, 180.0, 0.0, -0.0, 1e-300, -1e-300, 5e-324, 1e-14, -1e-14, 90.0, -90.0]),
)


@settings(max_examples=200, deadline=None)
@given(a=arrays(np.float64, (9, 3), elements=ANGLE), middle=st.integers(0, 2), proper=st.booleans())
def test_second_degrees_is_the_boolean_index_definition(a, middle, proper):
    """``d2 - where(mask, 360, 0)`` is ``d2[mask] -= 360`` bit for bit, -0.0 and tiny angles included."""
    p1 = [a[:, k].copy() for k in range(3)]
    ref = []
    for role, d in enumerate(p1):
        if role != middle:
            d2 = d + 180.0
            d2[d > 0] -= 360.0
        elif proper:
            d2 = -d
        else:
            d2 = 180.0 - d
            d2[d < 0] -= 360.0
        d2[d2 <= -180.0] += 360.0
        ref.append(d2)
    got = solutions.second_degrees(p1, middle, proper)
    for g, r in zip(got, ref):
        assert np.array_equal(_bits(g), _bits(r))
        assert (g > -180).all() and (g <= 180).all()


def test_frobenius_sums_in_row_major_order():
    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(500, 3, 3)), rng.normal(size=(500, 3, 3))
    acc = 0.0
    for m in range(3):
        for k in range(3):
            acc = acc + (X[:, m, k] - Y[:, m, k]) ** 2
    got = soa.frobenius(soa.from_array(X), soa.from_array(Y))
    assert np.array_equal(_bits(got), _bits(np.sqrt(acc)))
    np.testing.assert_allclose(got, np.linalg.norm(X - Y, axis=(1, 2)), rtol=1e-14)
    # constant (float) entries and arrays mixed, as elemental rotations have them
    Xs = soa.elemental(2, np.linspace(-3, 3, 7))
    got = soa.frobenius(Xs, soa.constant(np.eye(3)))
    want = np.linalg.norm(soa.to_array(Xs, 7) - np.eye(3), axis=(1, 2))
    np.testing.assert_allclose(got, want, rtol=1e-14)


def test_screen_in_blocks_equals_the_matrix_screen():
    """The blocked column screen finds the rows the (n, 3, 3) screen finds (NaN, inf, scaled, reflected)."""
    rng = np.random.default_rng(1)
    R = Rotation.random(N, random_state=2).as_matrix()
    bad = rng.choice(N, 400, replace=False)
    R[bad[:100], 0, 0] = np.nan
    R[bad[100:200], 2, 1] = np.inf
    R[bad[200:300]] *= 1.001
    R[bad[300:], 0] *= -1
    cols = [np.ascontiguousarray(R[:, i, j]) for i in range(3) for j in range(3)]
    finite, ortho, proper = rotation_screen_columns(cols)
    assert finite.shape == (N,)
    assert np.array_equal(finite & ortho & proper, rotation_mask(R))
    assert not (finite[bad[:200]]).any()
    assert not ortho[bad[200:300]].any() and not proper[bad[300:]].any()


def _table(path, n=9000):
    """An angle table and a matrix table (300w_lp) with rows at and near every system's lock, and rejects."""
    rng = np.random.default_rng(5)
    w = get_system("300w_lp")
    R = w.from_canonical(_canonical(n, seed=5))
    a = w.to_angles(R)[0]
    a[:300, 1] = rng.choice([90.0, -90.0, 89.99999], 300)  # at and near 300w_lp's own lock, as written
    a[600:620, 2] = np.nan  # rejected
    a[620:640, 1] = 1e9  # rejected
    pq.write_table(pa.table({"id": np.arange(n), "pitch": a[:, 0], "yaw": a[:, 1], "roll": a[:, 2]}), path)
    R = R.reshape(n, 9)
    R[600:620] *= -1  # reflections: rejected
    m = path.with_name("m.parquet")
    pq.write_table(pa.table({"id": np.arange(n), **{f"r{k // 3}{k % 3}": R[:, k] for k in range(9)}}), m)
    return path, m


@pytest.mark.parametrize("target", ["scipy_zyx", "aflw", "whenet", "6drepnet_6d"])
def test_convert_same_numbers_whatever_the_batch_size_and_threads(tmp_path, target):
    """Every column, bit for bit, for batch sizes across block boundaries and 1 or 3 threads."""
    for inp, rejected in zip(_table(tmp_path / "a.parquet"), (40, 20)):
        tables = []
        for batch, threads in ((65536, 1), (5000, 3), (1, 2), (soa.BLOCK + 1, 2)):
            if batch == 1:
                batch = 997  # many small batches
            out = tmp_path / f"o{batch}_{threads}.parquet"
            hpe("convert", inp, "-o", out, "--from", "300w_lp", "--to", target, "--rejects", tmp_path / "rej.csv",
                "--overwrite", "--batch-size", batch, "--threads", threads, "-q", ok=True)  # fmt: skip
            tables.append(pq.read_table(out))
        first = tables[0]
        assert first.num_rows == 9000 - rejected and first["gimbal_lock"].to_numpy().sum() > 0
        for t in tables[1:]:
            assert t.column_names == first.column_names
            for name in first.column_names:
                x, y = first[name].to_numpy(), t[name].to_numpy()
                assert np.array_equal(
                    _bits(x) if x.dtype == np.float64 else x, _bits(y) if y.dtype == np.float64 else y
                )
