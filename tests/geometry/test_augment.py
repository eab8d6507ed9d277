"""The augmentation library, tested physically.

A left/right-symmetric 3-D head is turned by a label, projected orthographically
into the image, and the 2-D landmarks are augmented. The projection of the same
head under the augmented label must land exactly on the augmented landmarks
(after re-indexing), for every label, every system and every augmentation. The
common shortcuts fail that test. Images are checked to the pixel with dots.
"""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import canonical_A, locate_dots
from hpe_cli.geometry.augment import (
    augment_batch,
    augment_boxes,
    augment_canonical,
    augment_points,
    augment_sample,
    pixel_affine,
    plane_matrix,
)
from hpe_cli.geometry.image_ops import opencv_rotation_matrix, warp_image
from hpe_cli.geometry.landmark_schemes import SCHEMES
from hpe_cli.rotation import get_system

DATA = Path(__file__).resolve().parents[2] / "hpe_cli" / "data"
W, H = 640, 480
S = np.diag([-1.0, 1.0, 1.0])


# ------------------------------------------------------------------------------------------------ the heads
def _whenet_head():
    """WHENet's 58-point head (canonical frame, exactly symmetric in x) and its own mirror permutation."""
    P = np.asarray(json.loads((DATA / "whenet_reference_head.json").read_text())["points"], dtype=float)
    d = np.linalg.norm((P * [-1, 1, 1])[:, None] - P[None], axis=2)
    perm = d.argmin(axis=1)
    assert d[np.arange(len(P)), perm].max() < 1e-9  # the head really is symmetric
    return P - P.mean(axis=0) * [1, 1, 0], perm


def _ibug_head(pupils=False):
    """The 68-point mean face in the canonical frame, made exactly symmetric under the ibug68 permutation."""
    P = np.load(DATA / "reference_3d_68_points_trans.npy").astype(float) * [1, -1, -1]  # y down, z in -> canonical
    P = P - P.mean(axis=0) * [1, 0, 0]
    perm = SCHEMES["ibug68"]
    P = (P + (P * [-1, 1, 1])[perm]) / 2
    if pupils:
        P = np.vstack([P, P[36:42].mean(axis=0), P[42:48].mean(axis=0)])
    return P * 8.0  # roughly the WHENet head's units


HEAD, HEAD_PERM = _whenet_head()


def project(A, P, scale=20.0, centre=(300.0, 250.0)):
    """Orthographic image of head points P (K, 3) under canonical labels A (..., 3, 3): u right, v down."""
    X = np.einsum("...ij,kj->...ki", A, P) * scale
    return np.stack([centre[0] + X[..., 0], centre[1] - X[..., 1]], axis=-1)


def physical_error(A, A2, op, angle, P=HEAD, perm=HEAD_PERM, centre=(300.0, 250.0), size=(W, H)):
    """Max pixel distance between the augmented 2-D landmarks and the projection under the augmented label."""
    M = plane_matrix(op, angle) if isinstance(op, str) else op
    moved = augment_points(project(A, P, centre=centre), M, size, perm)
    new_centre = augment_points(np.array([centre]), M, size, [0])[0]  # where the head's centre went
    return np.abs(moved - project(A2, P, centre=new_centre)).max()


def A_of(pyr):
    return canonical_A(np.atleast_2d(pyr))[0]


ANGLE = st.floats(-180, 180, allow_nan=False)
OPS = st.one_of(
    st.sampled_from([("hflip", None), ("vflip", None), ("hvflip", None)]),
    st.tuples(st.sampled_from(["rotate", "mirror"]), st.floats(-720, 720, allow_nan=False)),
)
SYSTEMS = ["300w_lp", "6drepnet", "scipy_zyx", "opencv", "whenet", "3ddfa_v2"]


# --------------------------------------------------------------------------------- SPEC §5 worked examples
def test_spec_worked_examples():
    out = augment_sample([20.0, -50.0, 15.0], op="rotate", angle=30, image_size=(W, H))
    np.testing.assert_allclose(out.angles, [43.511, -33.607, -19.343], atol=5e-4)
    out = augment_sample([0.0, 0.0, 0.0], op="vflip", image_size=(W, H))
    np.testing.assert_allclose(out.angles, [0.0, 0.0, 180.0], atol=1e-12)
    out = augment_sample([0.0, 0.0, 10.0], op="rotate", angle=25, image_size=(W, H))
    np.testing.assert_allclose(out.angles, [0.0, 0.0, -15.0], atol=1e-12)  # frontal: roll' = roll - phi


@given(ANGLE, st.floats(-89.9, 89.9), ANGLE)
def test_hflip_is_p_minus_y_minus_r(p, y, r):
    out = augment_sample([p, y, r], op="hflip", image_size=(W, H))
    np.testing.assert_allclose(out.canonical, A_of([p, -y, -r]), atol=1e-12)
    assert physical_error(A_of([p, y, r]), out.canonical, "hflip", None) < 1e-9


@given(ANGLE, ANGLE, ANGLE, st.floats(-720, 720))
def test_canonical_formulas_match_scipy(p, y, r, phi):
    A = A_of([p, y, r])
    rz = Rotation.from_euler("z", phi, degrees=True).as_matrix()
    np.testing.assert_allclose(augment_canonical(A, plane_matrix("rotate", phi)), rz @ A, atol=1e-12)
    # mirror about L_theta = the mirror about the x axis, conjugated by the rotation by theta
    half = Rotation.from_euler("z", phi / 2, degrees=True).as_matrix()
    refl = half @ np.diag([1.0, -1.0, 1.0]) @ half.T
    np.testing.assert_allclose(augment_canonical(A, plane_matrix("mirror", phi / 2)), refl @ A @ S, atol=1e-12)
    np.testing.assert_allclose(augment_canonical(A, plane_matrix("hvflip")), np.diag([-1.0, -1, 1]) @ A, atol=1e-15)


def test_named_flips_are_special_cases():
    np.testing.assert_allclose(plane_matrix("mirror", 90), plane_matrix("hflip"), atol=0)
    np.testing.assert_allclose(plane_matrix("mirror", 0), plane_matrix("vflip"), atol=0)
    np.testing.assert_allclose(plane_matrix("rotate", 180), plane_matrix("hvflip"), atol=0)
    np.testing.assert_allclose(plane_matrix("rotate", -270), [[0, -1], [1, 0]], atol=0)
    np.testing.assert_allclose(plane_matrix("hflip") @ plane_matrix("vflip"), plane_matrix("hvflip"), atol=0)


# ------------------------------------------------------------------------------------- the physical test
@given(ANGLE, ANGLE, ANGLE, OPS, st.sampled_from(SYSTEMS))
def test_projection_of_augmented_label_matches_augmented_landmarks(p, y, r, op, system):
    """Full angle range, every augmentation, labels given as angles of any system."""
    sysm = get_system(system)
    out = augment_sample([p, y, r], op=op[0], angle=op[1], image_size=(W, H), system=system)
    A = sysm.to_canonical(sysm.from_angles([[p, y, r]]))[0]
    # what a user gets back is angles in the same system: rebuild the label from them
    A2 = sysm.to_canonical(sysm.from_angles(out.angles[None]))[0]
    # near the lock the angles only keep p -+ r (round trip within gimbal_tol): a few hundredths of a pixel
    assert physical_error(A, A2, *op) < (0.05 if out.gimbal_lock else 1e-7)
    assert physical_error(A, out.canonical, *op) < 1e-9
    np.testing.assert_allclose(sysm.to_canonical(out.matrix), out.canonical, atol=1e-12)
    np.testing.assert_allclose(sysm.to_canonical(sysm.from_angles(out.angles_2[None]))[0], A2, atol=1e-3)


@given(st.lists(OPS, min_size=1, max_size=4), ANGLE, ANGLE, ANGLE)
def test_chains_of_augmentations(ops, p, y, r):
    """Composed augmentations (e.g. mirror then rotate) are one plane matrix, and stay physical."""
    A = A_of([p, y, r])
    M = np.eye(2)
    A2 = A
    for op, angle in ops:
        Mi = plane_matrix(op, angle)
        A2 = augment_canonical(A2, Mi)
        M = Mi @ M
    assert physical_error(A, A2, M, None) < 1e-9
    np.testing.assert_allclose(augment_canonical(A, M), A2, atol=1e-12)


@pytest.mark.parametrize("pupils", [False, True])
@given(ANGLE, ANGLE, ANGLE, OPS)
def test_ibug68_and_face70_schemes_on_a_face(pupils, p, y, r, op):
    """The shipped permutations do the re-indexing: index 36 stays the subject's right outer eye corner."""
    P = _ibug_head(pupils)
    perm = SCHEMES["face70" if pupils else "ibug68"]
    out = augment_sample([p, y, r], op=op[0], angle=op[1], image_size=(W, H))
    assert physical_error(A_of([p, y, r]), out.canonical, *op, P=P, perm=perm) < 1e-9


def test_mirror_without_reindexing_fails_the_physical_test():
    P = _ibug_head()
    A = A_of([10, 30, 5])
    out = augment_sample([10, 30, 5], op="hflip", image_size=(W, H))
    assert physical_error(A, out.canonical, "hflip", None, P=P, perm=SCHEMES["ibug68"]) < 1e-9
    assert physical_error(A, out.canonical, "hflip", None, P=P, perm=np.arange(68)) > 50


# --------------------------------------------------------------------------------- the shortcuts fail it
GENERIC = [(20, -50, 15), (-35, 25, 40), (10, 70, -20), (60, -10, 5), (-15, 35, -120)]


@pytest.mark.parametrize("pyr", GENERIC)
def test_vflip_shortcut_fails(pyr):
    p, y, r = pyr
    A = A_of(pyr)
    assert physical_error(A, augment_sample(pyr, op="vflip", image_size=(W, H)).canonical, "vflip", None) < 1e-9
    assert physical_error(A, A_of([-p, y, -r]), "vflip", None) > 50  # off by 180 degrees of roll
    assert physical_error(A, A_of([-p, y, 180 - r]), "vflip", None) < 1e-9  # what it should have been


@pytest.mark.parametrize("pyr", GENERIC)
@pytest.mark.parametrize("phi", [30.0, -45.0, 90.0])
def test_roll_shortcut_for_rotation_fails(pyr, phi):
    p, y, r = pyr
    A = A_of(pyr)
    assert (
        physical_error(A, augment_sample(pyr, op="rotate", angle=phi, image_size=(W, H)).canonical, "rotate", phi)
        < 1e-9
    )
    for sign in (1, -1):
        assert physical_error(A, A_of([p, y, r + sign * phi]), "rotate", phi) > 5


def test_roll_shortcut_only_holds_for_frontal_faces():
    A = A_of([0, 0, 12])
    assert physical_error(A, A_of([0, 0, 12 - 30]), "rotate", 30) < 1e-9


# ------------------------------------------------------------------------------- pixels: OpenCV agreement
@pytest.mark.parametrize("size", [(W, H), (121, 96), (96, 121), (7, 7)])
@pytest.mark.parametrize("phi", [0.0, 30.0, -137.25, 90.0, 180.0])
def test_pixel_affine_is_opencvs_rotation_about_the_pixel_centre(size, phi):
    np.testing.assert_allclose(
        pixel_affine(plane_matrix("rotate", phi), size), opencv_rotation_matrix(phi, size), atol=1e-12
    )
    w, h = size
    # and OpenCV's own call, spelled out
    np.testing.assert_allclose(
        opencv_rotation_matrix(phi, size), cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), phi, 1.0), atol=0
    )


def test_hflip_maps_x_to_w_minus_1_minus_x():
    pts = np.array([[0.0, 0.0], [W - 1.0, H - 1.0], [10.25, 20.5]])
    np.testing.assert_allclose(
        augment_points(pts, plane_matrix("hflip"), (W, H), [0, 1, 2]),
        [[W - 1, 0], [0, H - 1], [W - 11.25, 20.5]],
        atol=1e-12,
    )
    np.testing.assert_allclose(
        augment_points(pts, plane_matrix("vflip"), (W, H), [0, 1, 2]),
        [[0, H - 1], [W - 1, 0], [10.25, H - 21.5]],
        atol=1e-12,
    )


def test_rotation_is_counter_clockwise_on_screen():
    # a point right of the centre goes up (smaller row) under a small counter-clockwise turn
    c = ((W - 1) / 2, (H - 1) / 2)
    q = augment_points(np.array([[c[0] + 100, c[1]]]), plane_matrix("rotate", 90), (W, H))[0]
    np.testing.assert_allclose(q, [c[0], c[1] - 100], atol=1e-12)


def _grid_points(w, h, rng, margin=12, step=20):
    g = np.array(
        [(x, y) for x in np.arange(margin, w - margin, step) for y in np.arange(margin, h - margin, step)], dtype=float
    )
    return g + rng.uniform(-2, 2, g.shape)


def _render(pts, w, h, sigma=1.6):
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    img = np.zeros((h, w))
    for x, y in pts:
        img += np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma**2))
    return img


PIXEL_OPS = [
    ("hflip", None),
    ("vflip", None),
    ("hvflip", None),
    ("rotate", 30.0),
    ("rotate", 90.0),
    ("rotate", -137.3),
    ("mirror", 20.0),
    ("mirror", 45.0),
    ("mirror", -61.0),
]


@pytest.mark.parametrize("size", [(121, 96), (100, 81)])
@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
@pytest.mark.parametrize("op", PIXEL_OPS)
def test_moved_landmarks_land_on_the_moved_dots(size, dtype, op):
    w, h = size
    rng = np.random.default_rng(7)
    pts = _grid_points(w, h, rng)
    img = _render(pts, w, h)
    img = img.astype(np.float32) if dtype == np.float32 else np.clip(img * 250, 0, 255).astype(np.uint8)
    assert np.abs(locate_dots(img, pts) - pts).max() < 0.01  # the locator itself
    M = plane_matrix(*op)
    warped = warp_image(img, M)
    assert warped.shape == img.shape and warped.dtype == img.dtype
    moved = augment_points(pts, M, size, np.arange(len(pts)))
    inside = ((moved >= 9) & (moved <= np.array(size) - 10)).all(axis=1)
    assert inside.sum() >= len(pts) // 2
    err = np.abs(locate_dots(warped, moved[inside]) - moved[inside]).max()
    assert err < (0.02 if dtype == np.float32 else 0.03)
    # the common (W/2, H/2) centre misses by a visible fraction of a pixel
    N = pixel_affine(M, size)[:, :2]
    c = np.array([w / 2, h / 2])
    naive = cv2.warpAffine(img, np.c_[N, c - N @ c], (w, h))
    assert np.abs(locate_dots(naive, moved[inside]) - moved[inside]).max() > 0.25


def test_warp_image_keeps_channels_and_flips_exactly():
    img = np.random.default_rng(1).integers(0, 255, (9, 13, 3), dtype=np.uint8)
    np.testing.assert_array_equal(warp_image(img, plane_matrix("hflip")), img[:, ::-1])
    np.testing.assert_array_equal(warp_image(img, plane_matrix("vflip")), img[::-1])
    np.testing.assert_array_equal(warp_image(img, plane_matrix("rotate", 180)), img[::-1, ::-1])
    np.testing.assert_array_equal(warp_image(img, plane_matrix("rotate", 360)), img)
    sq = img[:, :9]
    np.testing.assert_array_equal(
        warp_image(sq, plane_matrix("rotate", 90)), cv2.rotate(sq, cv2.ROTATE_90_COUNTERCLOCKWISE)
    )
    with pytest.raises(ValueError, match="interpolation"):
        warp_image(img, plane_matrix("rotate", 10), interpolation="bogus")


# -------------------------------------------------------------------------------------------------- boxes
def test_flip_moves_the_box_exactly():
    box = np.array([[10.0, 20.0, 30.0, 40.0]])
    np.testing.assert_allclose(augment_boxes(box, plane_matrix("hflip"), (W, H)), [[W - 1 - 40, 20, 30, 40]])
    np.testing.assert_allclose(augment_boxes(box, plane_matrix("vflip"), (W, H)), [[10, H - 1 - 60, 30, 40]])
    # the box does not shrink to the landmarks for an exact move (auto), but does when asked
    lm = np.array([[[15.0, 25.0], [30.0, 50.0]]])
    lm2 = augment_points(lm, plane_matrix("hflip"), (W, H), [1, 0])
    np.testing.assert_allclose(augment_boxes(box, plane_matrix("hflip"), (W, H), lm2), [[W - 1 - 40, 20, 30, 40]])
    np.testing.assert_allclose(
        augment_boxes(box, plane_matrix("hflip"), (W, H), lm2, "landmarks"), [[W - 31, 25, 15, 25]]
    )


def test_rotation_box_is_the_box_of_the_rotated_landmarks_or_corners():
    box = np.array([[100.0, 100.0, 50.0, 50.0], [100.0, 100.0, 50.0, 50.0]])
    lm = np.array(
        [[[110.0, 110.0], [140.0, 130.0], [np.nan, np.nan]], [[np.nan, np.nan], [np.nan, np.nan], [np.nan, np.nan]]]
    )
    M = plane_matrix("rotate", 45)
    lm2 = augment_points(lm, M, (W, H))
    out = augment_boxes(box, M, (W, H), lm2)
    lo, hi = np.nanmin(lm2[0], axis=0), np.nanmax(lm2[0], axis=0)
    np.testing.assert_allclose(out[0], [*lo, *(hi - lo)])
    corners = augment_points(np.array([[100.0, 100], [150, 100], [100, 150], [150, 150]]), M, (W, H))
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    np.testing.assert_allclose(out[1], [*lo, *(hi - lo)])  # no landmarks: the corners' box
    np.testing.assert_allclose(out[1, 2:], [50 * np.sqrt(2)] * 2)


def test_clip_and_missing_boxes():
    box = np.array([[-5.0, 470.0, 30.0, 40.0], [np.nan, 0, 1, 1]])
    out = augment_boxes(box, plane_matrix("rotate", 0), (W, H), clip=True)
    np.testing.assert_allclose(out[0], [0, 470, 25, H - 1 - 470])
    assert np.isnan(out[1]).all()
    # clipping commutes with a flip: [0, W-1] maps to itself
    f = plane_matrix("hflip")
    np.testing.assert_allclose(
        augment_boxes(augment_boxes(box[:1], f, (W, H)), np.eye(2), (W, H), clip=True),
        augment_boxes(augment_boxes(box[:1], np.eye(2), (W, H), clip=True), f, (W, H)),
    )


# ---------------------------------------------------------------------------------- batch API and errors
def test_batch_equals_per_sample_with_per_row_angles():
    rng = np.random.default_rng(3)
    n = 50
    pyr = rng.uniform(-180, 180, (n, 3))
    lm = rng.uniform(0, 400, (n, 68, 2))
    lm[rng.random((n, 68)) < 0.1] = np.nan
    box = np.c_[rng.uniform(0, 300, (n, 2)), rng.uniform(10, 100, (n, 2))]
    sizes = rng.integers(200, 800, (n, 2))
    for op in ("rotate", "mirror"):
        ang = rng.uniform(-360, 360, n)
        out = augment_batch(pyr, lm, box, op=op, angle=ang, image_size=sizes, system="6drepnet")
        for i in range(0, n, 7):
            one = augment_sample(pyr[i], lm[i], box[i], op=op, angle=ang[i], image_size=sizes[i], system="6drepnet")
            np.testing.assert_allclose(out.angles[i], one.angles, atol=1e-9)
            np.testing.assert_allclose(out.matrix[i], one.matrix, atol=1e-12)
            np.testing.assert_allclose(out.landmarks[i], one.landmarks, atol=1e-9, equal_nan=True)
            np.testing.assert_allclose(out.bbox[i], one.bbox, atol=1e-9)
    # mixed rotations and mirrors in one batch, as matrices
    Ms = np.stack([plane_matrix("rotate", 10), plane_matrix("mirror", 10)])
    out = augment_batch(pyr[:2], lm[:2], op=Ms, image_size=(W, H))
    assert np.isfinite(out.angles).all()
    np.testing.assert_allclose(
        out.landmarks[1], augment_points(lm[1], Ms[1], (W, H), SCHEMES["ibug68"]), equal_nan=True
    )


def test_matrix_input_and_identity():
    R = get_system("6drepnet").from_angles([[10.0, 20.0, 30.0]])
    out = augment_batch(R, op="rotate", angle=0, image_size=(W, H), system="6drepnet")
    np.testing.assert_allclose(out.matrix, R, atol=1e-15)
    np.testing.assert_allclose(out.angles, [[10.0, 20.0, 30.0]], atol=1e-12)


def test_errors():
    with pytest.raises(ValueError, match="permutation"):
        augment_points(np.zeros((5, 2)), plane_matrix("hflip"), (W, H))
    with pytest.raises(ValueError, match="orthogonal"):
        augment_canonical(np.eye(3), 2 * np.eye(2))
    with pytest.raises(ValueError, match="expected op"):
        plane_matrix("shear", 3)
    with pytest.raises(ValueError, match="needs an angle"):
        plane_matrix("rotate")
    with pytest.raises(ValueError, match="takes no angle"):
        plane_matrix("hflip", 3)
    with pytest.raises(ValueError, match="image sizes"):
        pixel_affine(np.eye(2), (0, 10))
    with pytest.raises(ValueError, match="pose of shape"):
        augment_batch(np.zeros((2, 4)), op="hflip", image_size=(W, H))
    with pytest.raises(ValueError, match="scheme ibug68 has 68 landmarks, got 21"):
        augment_sample([0, 0, 0], np.zeros((21, 2)), op="hflip", image_size=(W, H), scheme="ibug68")
    with pytest.raises(ValueError, match="permutation"):  # 5 points, mirror, no scheme for 5
        augment_sample([0, 0, 0], np.zeros((5, 2)), op="vflip", image_size=(W, H))
    # rotations need no scheme
    out = augment_sample([0, 0, 0], np.zeros((5, 2)), op="rotate", angle=5, image_size=(W, H))
    assert out.landmarks.shape == (5, 2)
