"""torchvision v2 + HeadPose: the same labels as hpe_cli.geometry.augment, and physically right on real AFLW2000 faces.

Oracles: ``augment_batch`` (the numpy maths of SPEC §5); torchvision's own keypoint kernels moving the real
``pt3d_68`` landmarks of AFLW2000-3D, which the transformed pose must reproduce by orthographic projection.
"""

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from torchvision import tv_tensors  # noqa: E402
from torchvision.transforms import v2  # noqa: E402
from torchvision.transforms.v2 import functional as F  # noqa: E402

from conftest import REALDATA  # noqa: E402
from hpe_cli.geometry.augment import augment_batch  # noqa: E402
from hpe_cli.geometry.landmark_schemes import SCHEMES  # noqa: E402
from hpe_cli.rotation import get_system  # noqa: E402
from hpe_cli.torch import HeadPose, PermuteLandmarks, UndefinedPoseError, angles_to_canonical  # noqa: E402
from hpe_cli.torch import transforms as T  # noqa: E402

AFLW = REALDATA / "aflw2000_prnet"
S300 = get_system("300w_lp")
W, H = 120, 90


def _pose(pyr, size=(H, W)):
    return HeadPose(angles_to_canonical(torch.tensor(pyr, dtype=torch.float64), "300w_lp"), canvas_size=size)


def _A(pyr):
    return S300.to_canonical(S300.from_angles(np.asarray(pyr, dtype=float)))


PYR = np.random.default_rng(0).uniform([-60, -89, -60], [60, 89, 60], (16, 3))
PYR[0] = [10.0, 90.0, 20.0]  # at gimbal lock


@pytest.mark.parametrize(
    "fn, op, angle",
    [
        (F.horizontal_flip, "hflip", None),
        (F.vertical_flip, "vflip", None),
        (lambda p: F.rotate(p, 37.5), "rotate", 37.5),
        (lambda p: F.rotate(p, -90.0, expand=True), "rotate", -90.0),
        (lambda p: F.affine(p, 25.0, [7.0, -3.0], 1.3, [0.0, 0.0]), "rotate", -25.0),  # F.affine turns clockwise
    ],
)
def test_pose_kernels_equal_augment_batch(fn, op, angle):
    ref = augment_batch(PYR, op=op, angle=angle, image_size=(W, H))
    got = fn(_pose(PYR))
    assert isinstance(got, HeadPose)
    assert np.abs(got.as_subclass(torch.Tensor).numpy() - ref.canonical).max() < 1e-12


def test_flip_keypoints_equal_augment_batch_with_permutation():
    pts = np.random.default_rng(1).uniform(0, W - 1, (3, 68, 2))
    ref = augment_batch(PYR[:3], pts, op="hflip", image_size=(W, H), scheme="ibug68")
    kp = tv_tensors.KeyPoints(torch.tensor(pts), canvas_size=(H, W))
    img = tv_tensors.Image(torch.zeros(3, H, W, dtype=torch.uint8))
    _, kp2, pose2 = T.RandomHorizontalFlip(p=1.0, scheme="ibug68")(img, kp, _pose(PYR[:3]))
    assert np.abs(kp2.numpy() - ref.landmarks).max() < 1e-12
    assert np.abs(pose2.numpy() - ref.canonical).max() < 1e-12
    # torchvision's flip + PermuteLandmarks is the same
    kp3 = PermuteLandmarks("auto")(v2.RandomHorizontalFlip(p=1.0)(kp))
    assert np.abs(kp3.numpy() - ref.landmarks).max() < 1e-12


def test_rotation_keypoints_differ_from_augment_batch_by_the_half_pixel_centre_only():
    pts = np.random.default_rng(2).uniform(0, W - 1, (2, 5, 2))
    ref = augment_batch(PYR[:2], pts, op="rotate", angle=30.0, image_size=(W, H), scheme=None)
    kp = F.rotate(tv_tensors.KeyPoints(torch.tensor(pts), canvas_size=(H, W)), 30.0)
    N = np.array([[np.cos(np.deg2rad(30)), np.sin(np.deg2rad(30))], [-np.sin(np.deg2rad(30)), np.cos(np.deg2rad(30))]])
    offset = (np.eye(2) - N) @ [0.5, 0.5]  # torchvision turns points about (W/2, H/2), not ((W-1)/2, (H-1)/2)
    assert np.abs(kp.numpy() - ref.landmarks - offset).max() < 1e-9


def test_no_pose_meaning_raises():
    pose = _pose(PYR[:2])
    with pytest.raises(UndefinedPoseError, match="shear"):
        F.affine(pose, 10.0, [0, 0], 1.0, [5.0, 0.0])
    with pytest.raises(UndefinedPoseError, match="shear"):
        v2.RandomAffine(degrees=0, shear=(10, 20))(tv_tensors.Image(torch.zeros(3, H, W)), pose)
    with pytest.raises(UndefinedPoseError, match="perspective"):
        v2.RandomPerspective(p=1.0)(tv_tensors.Image(torch.zeros(3, H, W)), pose)
    with pytest.raises(UndefinedPoseError, match="elastic"):
        v2.ElasticTransform()(tv_tensors.Image(torch.zeros(3, H, W)), pose)
    with pytest.raises(UndefinedPoseError, match="aspect ratio"):
        F.resize(pose, [64, 64])  # 120x90 -> 64x64 squashes the face
    with pytest.raises(UndefinedPoseError, match="aspect ratio"):
        F.resized_crop(pose, 0, 0, 40, 80, [64, 64])
    with pytest.raises(UndefinedPoseError, match="canvas_size"):
        F.resize(HeadPose(pose.as_subclass(torch.Tensor)), [64, 64])


def test_exact_operations_keep_or_move_the_pose_and_canvas():
    pose = _pose(PYR[:2])
    A = pose.as_subclass(torch.Tensor)
    out = F.resize(pose, [60])  # shorter side 90 -> 60: uniform
    assert out.canvas_size == (60, 80) and torch.equal(out.as_subclass(torch.Tensor), A)
    out = F.resized_crop(pose, 5, 5, 50, 50, [224, 224])
    assert out.canvas_size == (224, 224) and torch.equal(out.as_subclass(torch.Tensor), A)
    out = F.rotate(pose, 30.0, expand=True)
    assert out.canvas_size != (H, W)
    assert F.pad(pose, [3, 4]).canvas_size == (H + 8, W + 6)
    assert F.center_crop(pose, [50, 50]).canvas_size == (50, 50)
    # colour transforms pass the pose through untouched
    img = tv_tensors.Image(torch.rand(3, H, W))
    _, same = v2.Compose([v2.ColorJitter(0.5, 0.5, 0.5), v2.GaussianBlur(3), v2.Grayscale(3)])(img, pose)
    assert torch.equal(same.as_subclass(torch.Tensor), A)
    # 90-degree turns and flips stay exact (signed permutations, no rounding)
    assert torch.equal(
        F.rotate(F.rotate(F.rotate(F.rotate(pose, 90.0), 90.0), 90.0), 90.0).as_subclass(torch.Tensor), A
    )
    assert torch.equal(F.horizontal_flip(F.horizontal_flip(pose)).as_subclass(torch.Tensor), A)


def test_batch_of_images_with_poses_through_compose():
    pipe = v2.Compose(
        [
            T.RandomHorizontalFlip(p=1.0),
            v2.RandomRotation((20, 20)),
            v2.RandomResizedCrop(32, scale=(0.5, 0.9), ratio=(1.0, 1.0)),
            v2.ToDtype(torch.float32, scale=True),
        ]
    )
    img = tv_tensors.Image(torch.randint(0, 255, (16, 3, H, W), dtype=torch.uint8))
    out_img, pose = pipe(img, _pose(PYR))
    assert out_img.shape == (16, 3, 32, 32) and out_img.dtype == torch.float32
    ref = augment_batch(
        augment_batch(PYR, op="hflip", image_size=(W, H)).angles, op="rotate", angle=20.0, image_size=(W, H)
    )
    assert np.abs(pose.numpy() - ref.canonical).max() < 1e-12


# ------------------------------------------------------------------------ physical test on real AFLW2000 faces
def _read(f):
    import cv2
    import scipy.io

    m = scipy.io.loadmat(f)
    img = cv2.imread(str(f.with_suffix(".jpg")))[:, :, ::-1]
    return img, m["Pose_Para"].ravel().astype(float), m["pt3d_68"].astype(float)


def _residual(A, X, q):
    """RMS pixel residual of q (L, 2) (rows down) against the orthographic image of X (L, 3) under A, best scale and shift.

    The canonical y axis is up, image rows go down: the projection is (x, -y) of A @ X.
    """
    P = (X @ A.T)[:, :2] * [1.0, -1.0]
    D = np.column_stack([P.reshape(-1), np.tile([1.0, 0.0], len(P)), np.tile([0.0, 1.0], len(P))])
    coef, *_ = np.linalg.lstsq(D, q.reshape(-1), rcond=None)
    return np.sqrt(np.mean((D @ coef - q.reshape(-1)) ** 2)), coef[0]


@pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")
@pytest.mark.parametrize("seed", range(6))
def test_v2_pipeline_on_aflw2000_moves_pose_and_landmarks_consistently(seed):
    files = sorted(AFLW.glob("*.mat"))
    f = files[seed * 2 % len(files)]
    img, P, p3 = _read(f)
    h, w = img.shape[:2]
    A = S300.to_canonical(S300.from_angles(np.rad2deg(P[None, :3])))[0]
    # the 3-D head of this image, in model orientation: p3 (x, H-1-y, z) = s A X + t (see test_cli_draw)
    Y = np.stack([p3[0], h - 1 - p3[1], p3[2]], -1)
    X = (Y - Y.mean(0)) @ A / P[6]
    q = p3[:2].T
    before, _ = _residual(A, X, q)
    assert before < 1e-3  # the fitted landmarks are exactly s A X + t (float32 rounding)

    torch.manual_seed(seed)
    flip = seed % 2 == 0
    steps = [
        T.RandomHorizontalFlip(p=1.0 if flip else 0.0, scheme="ibug68"),
        v2.RandomRotation(40),
        v2.RandomCrop((300, 320), pad_if_needed=True),
    ]
    if seed >= 3:
        steps.append(v2.RandomVerticalFlip(p=1.0))  # torchvision's own: points only, re-indexed below
        steps.append(PermuteLandmarks("ibug68"))
    pipe = v2.Compose(steps)
    image = tv_tensors.Image(torch.from_numpy(img.copy()).permute(2, 0, 1))
    kp = tv_tensors.KeyPoints(torch.tensor(q), canvas_size=(h, w))
    pose = HeadPose(torch.tensor(A)[None], canvas_size=(h, w))
    image2, kp2, pose2 = pipe(image, kp, pose)
    A2 = pose2.as_subclass(torch.Tensor)[0].numpy()
    assert image2.shape[-2:] == (300, 320) and pose2.canvas_size == (300, 320) == kp2.canvas_size
    mirrors = int(flip) + int(seed >= 3)
    Xm = (X * [-1.0, 1.0, 1.0])[SCHEMES["ibug68"]] if mirrors % 2 else X  # a mirror mirrors the head and swaps sides
    after, scale = _residual(A2, Xm, kp2.numpy())
    assert abs(after - before) < 1e-6 and abs(scale - P[6]) < 1e-9 * P[6]
    assert np.allclose(A2 @ A2.T, np.eye(3), atol=1e-12) and np.linalg.det(A2) > 0
    if mirrors % 2:  # the naive label (pose untouched by the mirror) fails the same test badly
        assert _residual(A, X, kp2.numpy())[0] > 1.0


@pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")
def test_v2_resized_crop_on_aflw2000_scales_the_residual_only():
    img, P, p3 = _read(AFLW / "image00050.mat")
    h, w = img.shape[:2]
    A = S300.to_canonical(S300.from_angles(np.rad2deg(P[None, :3])))[0]
    Y = np.stack([p3[0], h - 1 - p3[1], p3[2]], -1)
    X = (Y - Y.mean(0)) @ A / P[6]
    kp = tv_tensors.KeyPoints(torch.tensor(p3[:2].T), canvas_size=(h, w))
    pose = HeadPose(torch.tensor(A)[None], canvas_size=(h, w))
    torch.manual_seed(0)
    kp2, pose2 = v2.RandomResizedCrop(224, scale=(0.3, 0.6), ratio=(1.0, 1.0))(kp, pose)
    res, scale = _residual(pose2.as_subclass(torch.Tensor)[0].numpy(), X, kp2.numpy())
    assert res < 1e-3 and pose2.canvas_size == (224, 224)
