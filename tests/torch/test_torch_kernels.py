"""hpe_cli.torch kernels against the numpy core (SciPy for 6-D and geodesic), random and gimbal-lock rotations."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from scipy.spatial.transform import Rotation  # noqa: E402

from hpe_cli.rotation import builtin_systems, geodesic_deg  # noqa: E402
from hpe_cli.torch import (  # noqa: E402
    angles_to_canonical,
    canonical_to_angles,
    from_canonical,
    from_matrix,
    geodesic,
    geodesic_loss,
    maev,
    matrix_to_sixd,
    sixd_to_matrix,
    to_canonical,
    to_matrix,
)

SYSTEMS = sorted(builtin_systems())
ROLE = {"pitch": 0, "yaw": 1, "roll": 2}


def _angles(system, n, seed, lock_rows=0):
    """Random angles; the first ``lock_rows`` put the middle turn at, or within 1e-13..1 deg of, its lock."""
    rng = np.random.default_rng(seed)
    pyr = rng.uniform(-180, 180, (n, 3))
    mid = ROLE[system._intrinsic_turns()[1].angle]
    at = 0.0 if system.intrinsic_axes[0] == system.intrinsic_axes[2] else 90.0
    off = rng.choice([0.0, 1e-13, 1e-9, 1e-6, 1e-4, 1e-2, 1.0], lock_rows) * rng.choice([-1, 1], lock_rows)
    pyr[:lock_rows, mid] = rng.choice([at, -at, 180 - at], lock_rows) + off
    return pyr


def _wrapped(a, b):
    d = np.abs(np.asarray(a) - np.asarray(b)) % 360.0
    return np.minimum(d, 360.0 - d)


@pytest.mark.parametrize("name", SYSTEMS)
def test_kernels_match_numpy_float64_including_gimbal_lock(name):
    s = builtin_systems()[name]
    pyr = _angles(s, 600, 1, lock_rows=300)
    R = s.from_angles(pyr)
    Rt = to_matrix(torch.tensor(pyr), s)
    assert Rt.dtype == torch.float64
    assert np.abs(Rt.numpy() - R).max() < 1e-12
    p1, p2, locked, lock = s.to_angles(R)
    q1, q2, qlocked, qlock = from_matrix(torch.tensor(R), name)
    assert _wrapped(q1.numpy(), p1).max() < 1e-12
    assert _wrapped(q2.numpy(), p2).max() < 1e-12
    assert np.array_equal(qlocked.numpy(), locked) and np.abs(qlock.numpy() - lock).max() < 1e-15
    assert locked.sum() > 20  # the test reaches the lock
    A = s.to_canonical(R)
    assert np.abs(to_canonical(torch.tensor(R), s).numpy() - A).max() < 1e-15
    assert np.abs(from_canonical(torch.tensor(A), s).numpy() - R).max() < 1e-15
    assert np.abs(angles_to_canonical(torch.tensor(pyr), s).numpy() - A).max() < 1e-12
    assert _wrapped(canonical_to_angles(torch.tensor(A), s)[0].numpy(), p1).max() < 1e-12


@pytest.mark.parametrize("name", SYSTEMS)
def test_kernels_float32_to_1e6(name):
    s = builtin_systems()[name]
    pyr = _angles(s, 400, 2, lock_rows=200)
    R = s.from_angles(pyr)
    Rt = to_matrix(torch.tensor(pyr, dtype=torch.float32), s)
    assert Rt.dtype == torch.float32
    assert np.abs(Rt.double().numpy() - R).max() < 1e-6
    q1, q2, _, _ = from_matrix(torch.tensor(R, dtype=torch.float32), s)
    assert q1.dtype == torch.float32
    # compare as matrices: float32 angles carry 1e-5 deg of rounding, the rotation they rebuild 1e-6
    assert np.abs(s.from_angles(q1.double().numpy()) - R).max() < 1e-6
    assert np.abs(s.from_angles(q2.double().numpy()) - R).max() < 1e-6


@given(
    st.floats(-180, 180),
    st.floats(-180, 180),
    st.floats(-180, 180),
    st.sampled_from(SYSTEMS),
    st.sampled_from([0.0, 1e-12, 1e-7, 1e-3, None]),
)
def test_property_from_matrix_equals_numpy(p, y, r, name, lock_off):
    s = builtin_systems()[name]
    pyr = np.array([[p, y, r]])
    if lock_off is not None:
        mid = ROLE[s._intrinsic_turns()[1].angle]
        pyr[0, mid] = (0.0 if s.intrinsic_axes[0] == s.intrinsic_axes[2] else 90.0) + lock_off
    R = s.from_angles(pyr)
    p1, p2, locked, _ = s.to_angles(R)
    q1, q2, qlocked, _ = from_matrix(torch.tensor(R), s)
    assert _wrapped(q1.numpy(), p1).max() < 1e-12 and _wrapped(q2.numpy(), p2).max() < 1e-12
    assert bool(qlocked[0]) == bool(locked[0])


def test_leading_dimensions_and_scipy_oracle():
    pyr = np.random.default_rng(3).uniform(-90, 90, (4, 5, 3))
    R = to_matrix(torch.tensor(pyr), "scipy_zyx")
    assert R.shape == (4, 5, 3, 3)
    # scipy_zyx: SciPy's intrinsic ZYX (yaw, pitch, roll) in its own frame
    ref = Rotation.from_euler("ZYX", pyr.reshape(-1, 3)[:, [1, 0, 2]], degrees=True).as_matrix()
    assert np.abs(R.reshape(-1, 3, 3).numpy() - ref).max() < 1e-12


def test_sixd_roundtrip_and_gram_schmidt_oracle():
    R = torch.tensor(Rotation.random(50, random_state=4).as_matrix())
    assert torch.allclose(sixd_to_matrix(matrix_to_sixd(R)), R, atol=1e-14)
    x = torch.randn(50, 6, dtype=torch.float64, generator=torch.Generator().manual_seed(5))
    M = sixd_to_matrix(x)
    # oracle: QR of the two columns (Gram-Schmidt), third column their cross product
    for k in range(5):
        q, rr = np.linalg.qr(np.stack([x[k, :3].numpy(), x[k, 3:].numpy()], -1))
        q = q * np.sign(np.diag(rr))
        ref = np.column_stack([q, np.cross(q[:, 0], q[:, 1])])
        assert np.abs(M[k].numpy() - ref).max() < 1e-12
    assert torch.autograd.gradcheck(sixd_to_matrix, (x[:4].clone().requires_grad_(),))


def test_geodesic_matches_numpy_and_is_accurate_at_0_and_180():
    R1 = Rotation.random(200, random_state=6).as_matrix()
    R2 = Rotation.random(200, random_state=7).as_matrix()
    d = torch.rad2deg(geodesic(torch.tensor(R1), torch.tensor(R2))).numpy()
    assert np.abs(d - geodesic_deg(R1, R2)).max() < 1e-10
    for angle in (1e-7, 180 - 1e-6):
        R = torch.tensor(
            Rotation.from_rotvec([0.3, -0.5, 0.81] / np.linalg.norm([0.3, -0.5, 0.81]) * np.deg2rad(angle)).as_matrix()
        )[None]
        got = torch.rad2deg(geodesic(torch.eye(3, dtype=torch.float64)[None], R)).item()
        assert abs(got - angle) < 1e-9


@pytest.mark.parametrize("angle", [0.0, 180.0, 1e-9, 90.0])
def test_geodesic_loss_gradients_finite_at_0_and_180(angle):
    axis = np.array([0.2, 0.9, -0.4]) / np.linalg.norm([0.2, 0.9, -0.4])
    target = torch.tensor(Rotation.from_rotvec(axis * np.deg2rad(angle)).as_matrix())[None]
    x = matrix_to_sixd(torch.eye(3, dtype=torch.float64)[None]).clone().requires_grad_()
    loss = geodesic_loss(sixd_to_matrix(x), target)
    loss.backward()
    assert torch.isfinite(x.grad).all()
    assert abs(np.rad2deg(loss.item()) - angle) < 1e-7
    R = torch.eye(3, dtype=torch.float64)[None].clone().requires_grad_()
    geodesic_loss(R, target, reduction="sum").backward()
    assert torch.isfinite(R.grad).all()


def test_maev_oracle():
    R1 = Rotation.random(30, random_state=8).as_matrix()
    R2 = Rotation.random(30, random_state=9).as_matrix()
    cos = np.clip(np.einsum("nik,nik->nk", R1, R2), -1, 1)  # column k of each
    ref = np.rad2deg(np.arccos(cos))
    got = maev(torch.tensor(R1), torch.tensor(R2), reduction="none").numpy()
    assert np.abs(got - ref).max() < 1e-6
    assert abs(maev(torch.tensor(R1), torch.tensor(R2)).item() - ref.mean()) < 1e-6
    from hpe_cli.metrics.rotation_errors import maev_deg  # the numpy metric of hpe evaluate

    assert np.abs(np.asarray(maev_deg(R1, R2)) - got).max() < 1e-6


def test_errors():
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        to_matrix(torch.zeros(4, 2), "300w_lp")
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\)"):
        from_matrix(torch.zeros(4, 3), "300w_lp")
    with pytest.raises(ValueError, match="reduction"):
        geodesic_loss(torch.eye(3)[None], torch.eye(3)[None], reduction="max")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_kernels_stay_on_device_and_match_cpu():
    from torchvision.transforms.v2 import functional as F

    from hpe_cli.torch import HeadPose

    pyr = torch.tensor(_angles(builtin_systems()["300w_lp"], 256, 10, lock_rows=64))
    to_matrix(pyr.cuda(), "6drepnet")  # warm-up (constant frames are copied to the device once)
    for dtype in (torch.float32, torch.float64):
        x = pyr.to("cuda", dtype)
        to_canonical(from_canonical(torch.eye(3, device="cuda", dtype=dtype), "biwi"), "biwi")  # warm the constants
        torch.cuda.set_sync_debug_mode("error")  # any device -> host synchronisation in the kernels raises
        try:
            R = to_matrix(x, "6drepnet")
            p1, _, locked, _ = from_matrix(R, "6drepnet")
            A = to_canonical(R, "6drepnet")
            to_canonical(from_canonical(A, "biwi"), "biwi")
            geodesic(A, A.flip(0))
        finally:
            torch.cuda.set_sync_debug_mode("default")
        assert R.is_cuda and p1.is_cuda and locked.is_cuda and A.is_cuda
        tol = 1e-6 if dtype == torch.float32 else 1e-12
        assert (R.cpu() - to_matrix(pyr.to(dtype), "6drepnet")).abs().max() < tol
        pose = HeadPose(A, canvas_size=(224, 224))
        for out in (F.horizontal_flip(pose), F.rotate(pose, 33.0), F.resized_crop(pose, 0, 0, 100, 100, [224, 224])):
            assert out.is_cuda
        loss = geodesic_loss(A, A.flip(0))
        assert loss.is_cuda
