"""HeadPoseDataset fast path (size=, hflip=, cached pose tables, __getitems__) and the on_undefined policy."""

import cv2
import numpy as np
import pandas as pd
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from torchvision.transforms import v2
from torchvision.transforms.v2 import functional as F

from conftest import REALDATA
from hpe_cli import write_labels
from hpe_cli.geometry.crop import points_to_crop
from hpe_cli.rotation import get_system
from hpe_cli.torch import HeadPose, HeadPoseDataset, UndefinedPoseError, angles_to_canonical
from hpe_cli.torch import transforms as T

AFLW = REALDATA / "aflw2000_prnet"
needs_aflw = pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")


def _labels(tmp_path, n=8, w=96, h=80):
    rng = np.random.default_rng(0)
    names = []
    for k in range(n):
        name = f"img{k}.png"
        cv2.imwrite(str(tmp_path / name), rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
        names.append(name)
    df = pd.DataFrame({"file": names})
    df[["pitch", "yaw", "roll"]] = rng.uniform(-70, 70, (n, 3))
    df[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]] = np.column_stack(
        [rng.uniform(-5, 40, n), rng.uniform(-5, 30, n), rng.uniform(20, 50, n), rng.uniform(20, 50, n)]
    )
    lm = rng.uniform(10, 60, (n, 5, 2))
    for i in range(5):
        df[f"lm{i}_x"], df[f"lm{i}_y"] = lm[:, i, 0], lm[:, i, 1]
    return write_labels(df, tmp_path / "labels.parquet", system="300w_lp"), df, lm


PERM = [4, 3, 2, 1, 0]


# ------------------------------------------------------------------------------------------ policy
def test_policy_on_a_pose_tensor_raise_drop_keep_and_the_flag_persists():
    A = angles_to_canonical(torch.tensor([[10.0, 30.0, 5.0]], dtype=torch.float64), "300w_lp")
    with pytest.raises(UndefinedPoseError, match="aspect ratio.*on_undefined"):
        F.resize(HeadPose(A, canvas_size=(64, 64)), [64, 32])
    drop = F.resize(HeadPose(A, canvas_size=(64, 64), on_undefined="drop"), [64, 32])
    assert drop.undefined and drop.isnan().all() and drop.canvas_size == (64, 32)
    keep = F.resize(HeadPose(A, canvas_size=(64, 64), on_undefined="keep"), [64, 32])
    assert keep.undefined and torch.equal(keep.as_subclass(torch.Tensor), A) and keep.canvas_size == (64, 32)
    later = F.horizontal_flip(F.rotate(keep, 30.0))  # the flag survives exact steps; the policy too
    assert later.undefined and later.on_undefined == "keep"
    assert later.clone().undefined and HeadPose(later).undefined
    ok = F.resize(HeadPose(A, canvas_size=(64, 64), on_undefined="drop"), [32, 32])
    assert not ok.undefined and torch.equal(ok.as_subclass(torch.Tensor), A)
    for op in (
        lambda p: F.affine(p, 0.0, [0, 0], 1.0, [10.0, 0.0]),
        lambda p: F.perspective(p, [[0, 0], [63, 0], [63, 63], [0, 63]], [[3, 1], [60, 0], [63, 63], [0, 60]]),
        lambda p: F.pad(p, [2], padding_mode="reflect"),
    ):
        assert op(HeadPose(A, canvas_size=(64, 64), on_undefined="keep")).undefined
        with pytest.raises(UndefinedPoseError):
            op(HeadPose(A, canvas_size=(64, 64)))
    with pytest.raises(UndefinedPoseError, match="five_crop"):  # a tuple of crops never has one pose
        F.five_crop(HeadPose(A, canvas_size=(64, 64), on_undefined="keep"), [32, 32])
    with pytest.raises(ValueError, match="on_undefined"):
        HeadPose(A, on_undefined="ignore")


@needs_aflw
def test_6drepnet_recipe_runs_unmodified_with_drop_or_keep():
    """6DRepNet trains with RandomResizedCrop(224, scale=(0.8, 1)) (aspect 3/4..4/3): no exact pose after it."""
    recipe = v2.Compose([v2.RandomResizedCrop(224, scale=(0.8, 1)), v2.ToDtype(torch.float32, scale=True)])
    raising = HeadPoseDataset(AFLW, crop=0.2, transform=recipe)
    torch.manual_seed(0)
    errors = 0
    for k in range(len(raising)):
        try:
            raising[k]
        except UndefinedPoseError:
            errors += 1
    assert errors >= 10  # almost every draw changes the aspect ratio
    plain = HeadPoseDataset(AFLW, crop=0.2)
    for policy in ("drop", "keep"):
        ds = HeadPoseDataset(AFLW, crop=0.2, transform=recipe, on_undefined=policy)
        torch.manual_seed(0)
        batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=16)))
        assert batch["image"].shape == (16, 3, 224, 224)
        flag = batch["pose_undefined"]
        assert flag.dtype == torch.bool and flag.sum() >= 10
        ref = torch.stack([plain[k]["matrix"] for k in range(16)])
        if policy == "drop":
            assert batch["matrix"][flag].isnan().all() and batch["angles"][flag].isnan().all()
            assert not batch["gimbal_lock"][flag].any()
        else:
            assert torch.allclose(batch["matrix"][flag], ref[flag], atol=1e-7)
        assert torch.allclose(batch["matrix"][~flag], ref[~flag], atol=1e-7)  # uniform draws: exact, unmarked


@needs_aflw
def test_landmarks_none_switches_off_the_output_only():
    with_lm = HeadPoseDataset(AFLW, crop=0.1)  # .mat: no bbox columns, the crop box is pt2d's
    without = HeadPoseDataset(AFLW, crop=0.1, landmarks=None)
    for k in (0, 5, 11):
        a, b = with_lm[k], without[k]
        assert "landmarks" in a and "landmarks" not in b
        assert a["image"].shape == b["image"].shape and torch.equal(a["image"], b["image"])
    assert without[0]["image"].shape[-1] < 450  # cropped, not the whole 450x450 image


# ------------------------------------------------------------------------------------------ fast path
def test_size_and_hflip_equal_the_v2_flip_and_the_oracles(tmp_path):
    path, df, lm = _labels(tmp_path)
    fast = HeadPoseDataset(path, system="6drepnet", crop=0.3, size=48, hflip=1.0, flip_scheme=PERM)
    slow = HeadPoseDataset(
        path, system="6drepnet", crop=0.3, size=48, transform=T.RandomHorizontalFlip(p=1.0, scheme=PERM)
    )
    plain = HeadPoseDataset(path, system="6drepnet", crop=0.3, size=48)
    s300, s6d = get_system("300w_lp"), get_system("6drepnet")
    for k in range(len(df)):
        a, b, c = fast[k], slow[k], plain[k]
        assert torch.equal(a["image"], b["image"]) and torch.equal(a["image"], c["image"].flip(-1))
        for key in ("matrix", "angles", "canonical", "box", "landmarks"):
            assert torch.allclose(a[key], b[key], atol=1e-7, rtol=0), key
        assert a["gimbal_lock"] == b["gimbal_lock"] and not a["pose_undefined"]
        # oracle: a mirror is (p, -y, -r) in 300W-LP's system, then 6DRepNet's matrix of it
        p, y, r = df.loc[k, ["pitch", "yaw", "roll"]]
        R = s6d.from_canonical(s300.to_canonical(s300.from_angles([[p, -y, -r]])))[0]
        assert np.abs(a["matrix"].double().numpy() - R).max() < 1e-6
        # landmarks: cv2.resize's pixel-centre mapping into the crop, then x -> 47 - x and re-indexed
        top, left, hh, ww = fast._rects[0][k]
        ref = points_to_crop(lm[k : k + 1], [[left, top, left + ww, top + hh]], size=(48, 48))[0]
        ref = ref[PERM] * [-1, 1] + [47, 0]
        assert np.abs(a["landmarks"].double().numpy() - ref).max() < 1e-5
    # the crop resized by OpenCV: the pixels of a bare cv2 loop
    img = cv2.imread(str(tmp_path / df.loc[3, "file"]))[:, :, ::-1]
    top, left, hh, ww = plain._rects[0][3]
    pad = np.zeros((hh, ww, 3), np.uint8)
    y0, x0, y1, x1 = max(top, 0), max(left, 0), min(top + hh, 80), min(left + ww, 96)
    pad[y0 - top : y1 - top, x0 - left : x1 - left] = img[y0:y1, x0:x1]
    assert np.array_equal(plain[3]["image"].permute(1, 2, 0).numpy(), cv2.resize(pad, (48, 48)))


def test_getitems_batches_equal_single_items_for_random_rotations(tmp_path):
    path, _, _ = _labels(tmp_path)
    ds = HeadPoseDataset(
        path, system="biwi", crop=0.2, size=40, hflip=0.5, flip_scheme=PERM, transform=v2.RandomRotation(35)
    )
    torch.manual_seed(3)
    batch = ds.__getitems__(list(range(8)))
    torch.manual_seed(3)
    single = [ds[k] for k in range(8)]
    biwi = get_system("biwi")
    for a, b in zip(batch, single):
        for key in ("matrix", "angles", "canonical", "landmarks", "image"):
            assert torch.equal(a[key], b[key]), key
        R = biwi.from_canonical(a["canonical"].double().numpy()[None])[0]
        assert np.abs(a["matrix"].double().numpy() - R).max() < 1e-6
        assert np.abs(biwi.from_angles(a["angles"].double().numpy()[None])[0] - R).max() < 1e-5


def test_random_hflip_in_two_workers_moves_each_pose_with_its_image(tmp_path):
    path, _, _ = _labels(tmp_path)
    ds = HeadPoseDataset(path, crop=0.25, size=32, hflip=0.5, flip_scheme=PERM)
    plain = HeadPoseDataset(path, crop=0.25, size=32)
    loader = torch.utils.data.DataLoader(ds, batch_size=4, num_workers=2)
    flips = 0
    for batch in loader:
        for n, i in enumerate(batch["index"].tolist()):
            ref = plain[i]
            flipped = not torch.equal(batch["image"][n], ref["image"])
            assert flipped == torch.equal(batch["image"][n], ref["image"].flip(-1))
            want = ref["angles"] * torch.tensor([1.0, -1.0, -1.0]) if flipped else ref["angles"]
            assert torch.allclose(batch["angles"][n], want, atol=1e-4)
            flips += flipped
    assert 0 < flips < len(ds)


def test_size_of_a_non_square_crop_follows_the_policy(tmp_path):
    path, _, _ = _labels(tmp_path)
    with pytest.raises(UndefinedPoseError, match="aspect ratio"):
        HeadPoseDataset(path, crop=0.2, square=False, size=32)[0]
    s = HeadPoseDataset(path, crop=0.2, square=False, size=32, on_undefined="keep")[0]
    assert s["pose_undefined"] and s["image"].shape == (3, 32, 32) and not s["matrix"].isnan().any()
    s = HeadPoseDataset(path, crop=0.2, square=False, size=32, on_undefined="drop")[0]
    assert s["pose_undefined"] and s["matrix"].isnan().all()


def test_bad_arguments(tmp_path):
    path, _, _ = _labels(tmp_path, n=1)
    for kw, msg in (
        ({"on_undefined": "skip"}, "on_undefined"),
        ({"hflip": 1.5}, "hflip"),
        ({"size": 0}, "size"),
        ({"interpolation": "bilinear"}, "interpolation"),
    ):
        with pytest.raises(ValueError, match=msg):
            HeadPoseDataset(path, **kw)
    with pytest.raises(ValueError, match="permutation"):
        HeadPoseDataset(path, hflip=0.5)  # 5 landmarks: no scheme has 5 points


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_policy_on_cuda_poses():
    A = angles_to_canonical(torch.tensor([[10.0, 30.0, 5.0]], dtype=torch.float64), "300w_lp").cuda()
    out = F.resized_crop(HeadPose(A, canvas_size=(64, 64), on_undefined="drop"), 0, 0, 40, 20, [32, 32])
    assert out.is_cuda and out.undefined and out.isnan().all()


class _NotTakenOver(T.RandomHorizontalFlip):
    """The same flip as a subclass: the dataset leaves subclasses to torchvision (the reference path)."""


@pytest.mark.parametrize("p", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("then", ["nothing", "rotation"])
def test_a_leading_flip_in_transform_is_done_in_the_decode_step(tmp_path, p, then):
    """``transform=T.RandomHorizontalFlip(p)`` (alone or first in ``v2.Compose``) runs as ``hflip=p``: the same
    images, poses to float rounding, and the same random draws, so a random transform after it draws alike."""
    path, df, _ = _labels(tmp_path)

    def make(cls):
        flip = cls(p=p, scheme=PERM)
        t = flip if then == "nothing" else v2.Compose([flip, v2.RandomRotation(30)])
        return HeadPoseDataset(path, system="6drepnet", crop=0.3, size=48, transform=t)

    fast, slow = make(T.RandomHorizontalFlip), make(_NotTakenOver)
    assert fast.hflip == p and (fast._transform is None) == (then == "nothing")  # taken over
    assert slow.hflip == 0 and slow._transform is slow.transform  # left to torchvision
    for seed in (0, 1):
        torch.manual_seed(seed)
        a = [fast[k] for k in range(len(df))] + fast.__getitems__(list(range(len(df))))
        torch.manual_seed(seed)
        b = [slow[k] for k in range(len(df))] + slow.__getitems__(list(range(len(df))))
        for x, y in zip(a, b):
            assert torch.equal(x["image"], y["image"])
            for key in ("matrix", "angles", "canonical", "box", "landmarks"):
                assert torch.allclose(x[key], y[key], atol=1e-5, rtol=0), key
            assert x["gimbal_lock"] == y["gimbal_lock"] and x["pose_undefined"] == y["pose_undefined"]
    torch.manual_seed(3)
    [fast[k] for k in range(4)]
    after_fast = torch.rand(())
    torch.manual_seed(3)
    [slow[k] for k in range(4)]
    assert torch.rand(()) == after_fast  # one draw per sample on both paths, p = 1 included


def test_a_flip_not_first_or_with_hflip_stays_in_torchvision(tmp_path):
    path, _, _ = _labels(tmp_path)
    flip = T.RandomHorizontalFlip(p=1.0, scheme=PERM)
    later = HeadPoseDataset(path, crop=0.3, size=48, transform=v2.Compose([v2.RandomRotation(5), flip]))
    both = HeadPoseDataset(path, crop=0.3, size=48, hflip=0.5, flip_scheme=PERM, transform=flip)
    assert later.hflip == 0 and later._transform is later.transform
    assert both.hflip == 0.5 and both._transform is flip
