"""hpe augment against independent oracles: cv2 moves a blob drawn at each landmark / head centre, SciPy composes
the rotation; image sizes are checked, the image commit is atomic, collisions are named."""

import os

import cv2
import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe
from hpe_cli.geometry.landmark_schemes import flip_permutation

W, H = 160, 120


def a300(p, y, r):
    """300W-LP's A = Rx(p)^T Ry(y)^T Rz(r)^T, from SciPy."""
    return Rotation.from_euler("ZYX", np.column_stack([r, y, p]), degrees=True).as_matrix().transpose(0, 2, 1)


def geodesic(A, B):
    return np.degrees(np.linalg.norm(Rotation.from_matrix(np.swapaxes(A, -1, -2) @ B).as_rotvec(), axis=-1))


def blob(u, v, w=W, h=H, sigma=1.5):
    yy, xx = np.mgrid[0:h, 0:w]
    return np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma**2)).astype(np.float32)


def centroid(img):
    yy, xx = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    m = img.sum()
    return (xx * img).sum() / m, (yy * img).sum() / m


def cv2_transform(img, how):
    """The oracle: OpenCV's own operation for each augmentation."""
    kind, arg = how
    if kind == "hflip":
        return cv2.flip(img, 1)
    if kind == "rotate":
        P = cv2.getRotationMatrix2D(((img.shape[1] - 1) / 2, (img.shape[0] - 1) / 2), arg, 1.0)
        return cv2.warpAffine(img, P, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR)
    if kind == "scale":
        h, w = img.shape[:2]
        return cv2.resize(
            img, (round(w * arg), round(h * arg)), interpolation=cv2.INTER_AREA if arg < 1 else cv2.INTER_LINEAR
        )
    x, y, w, h = arg
    return img[y : y + h, x : x + w]


CASES = [
    (("hflip", None), ["--hflip"]),
    (("rotate", 33.0), ["--rotate", "33"]),
    (("rotate", -120.0), ["--rotate", "-120"]),
    (("crop", (20, 10, 100, 90)), ["--crop", 20, 10, 100, 90]),
    (("scale", 0.5), ["--scale", "0.5"]),
    (("scale", 2.0), ["--scale", "2"]),
]


@pytest.mark.parametrize("how,args", CASES, ids=["hflip", "rot33", "rot-120", "crop", "half", "double"])
def test_landmarks_and_tdx_tdy_land_on_the_moved_pixels(tmp_path, how, args):
    rng = np.random.default_rng(4)
    n_lm = 21  # AFLW's 21 points: a mirror re-indexes them with its left/right pairs
    lm = np.column_stack([rng.uniform(50, 110, n_lm), rng.uniform(40, 80, n_lm)])
    td = np.array([70.3, 41.7])  # Pose_Para: tdy counts from the bottom row
    row = {
        "image": "a.png",
        "pitch": 10.0,
        "yaw": -35.0,
        "roll": 20.0,
        "tdx": td[0],
        "tdy": td[1],
        "tdz": 0.0,
        "scale": 0.001,
        "image_width": W,
        "image_height": H,
    }
    row.update({f"lm{i}_{a}": lm[i, k] for i in range(n_lm) for k, a in enumerate("xy")})
    pd.DataFrame([row]).to_parquet(tmp_path / "in.parquet")
    res = hpe("augment", tmp_path / "in.parquet", "-o", tmp_path / "out.parquet", *args)
    assert res.exit_code == 0, res.output
    out = pd.read_parquet(tmp_path / "out.parquet").iloc[0]
    wo, ho = (
        (how[1][2], how[1][3])
        if how[0] == "crop"
        else (round(W * how[1]), round(H * how[1]))
        if how[0] == "scale"
        else (W, H)
    )
    assert (out.image_width, out.image_height) == (wo, ho)
    perm = flip_permutation("aflw21") if how[0] == "hflip" else np.arange(n_lm)
    for i in range(n_lm):
        j = perm[i]  # output landmark i is input landmark perm[i], moved
        u, v = centroid(cv2_transform(blob(*lm[j]), how))
        assert abs(out[f"lm{i}_x"] - u) < 0.05 and abs(out[f"lm{i}_y"] - v) < 0.05, (i, j)
    u, v = centroid(cv2_transform(blob(td[0], H - 1 - td[1]), how))
    assert abs(out.tdx - u) < 0.05 and abs((ho - 1 - out.tdy) - v) < 0.05
    assert out.scale == pytest.approx(0.001 * (how[1] if how[0] == "scale" else 1.0))
    # the label, against SciPy: a turn by phi counter-clockwise on screen is Rz(phi) about the camera axis
    A = a300([10.0], [-35.0], [20.0])[0]
    if how[0] == "rotate":
        want = Rotation.from_euler("z", how[1], degrees=True).as_matrix() @ A
    elif how[0] == "hflip":
        want = a300([10.0], [35.0], [-20.0])[0]  # the mirror image of a head: yaw and roll change sign
    else:
        want = A  # a crop moves the origin only; a resize changes lengths only
    got = a300([out.pitch], [out.yaw], [out.roll])[0]
    assert geodesic(want, got) < 1e-6


def test_image_size_disagreement_is_a_reject_never_a_transform(tmp_path):
    """README case: --image-size 450 450 on labels of 1920x1080 frames rejected every row (boxes were at x = -656)."""
    t = pd.DataFrame(
        {
            "image": ["a.jpg", "b.jpg"],
            "pitch": 0.0,
            "yaw": 0.0,
            "roll": 0.0,
            "bbox_x": [100.0, 5.0],
            "bbox_y": 50.0,
            "bbox_w": 80.0,
            "bbox_h": 80.0,
            "image_width": [1920, 450],
            "image_height": [1080, 450],
        }
    )
    t.to_parquet(tmp_path / "in.parquet")
    res = hpe("augment", tmp_path / "in.parquet", "-o", tmp_path / "o.parquet", "--image-size", 450, 450, "--hflip")
    assert (
        res.exit_code == 1
        and "row 1: image size: image_width/image_height is 1920x1080, --image-size says 450x450" in res.output
        and not (tmp_path / "o.parquet").exists()
    )
    res = hpe(
        "augment",
        tmp_path / "in.parquet",
        "-o",
        tmp_path / "o.parquet",
        "--image-size",
        450,
        450,
        "--hflip",
        "--rejects",
        tmp_path / "rej.csv",
    )
    assert res.exit_code == 0, res.output
    o = pd.read_parquet(tmp_path / "o.parquet")
    assert o["bbox_x"].tolist() == [449 - 5 - 80.0] and pd.read_csv(tmp_path / "rej.csv")["row"].tolist() == [1]
    # without --image-size: each row's own size
    res = hpe("augment", tmp_path / "in.parquet", "-o", tmp_path / "o2.parquet", "--hflip")
    assert res.exit_code == 0, res.output
    assert pd.read_parquet(tmp_path / "o2.parquet")["bbox_x"].tolist() == [1919 - 100 - 80.0, 449 - 5 - 80.0]
    # every row rejected: exit 1 even with --rejects, nothing written
    t.iloc[:1].to_parquet(tmp_path / "one.parquet")
    res = hpe(
        "augment",
        tmp_path / "one.parquet",
        "-o",
        tmp_path / "o3.parquet",
        "--image-size",
        450,
        450,
        "--hflip",
        "--rejects",
        tmp_path / "rej3.csv",
    )
    assert res.exit_code == 1 and "all 1 row(s) rejected" in res.output
    assert not (tmp_path / "o3.parquet").exists()
    assert len(pd.read_csv(tmp_path / "rej3.csv")) == 1  # the rejects file still says why (issue 35)
    # no size anywhere: a usage error
    t.drop(columns=["image_width", "image_height"]).to_parquet(tmp_path / "nosize.parquet")
    res = hpe("augment", tmp_path / "nosize.parquet", "-o", tmp_path / "o4.parquet", "--hflip")
    assert res.exit_code == 2 and "expected the image size" in res.output


def _images(tmp_path, names, w=W, h=H):
    root = tmp_path / "imgs"
    for k, n in enumerate(names):
        (root / n).parent.mkdir(parents=True, exist_ok=True)
        img = np.zeros((h, w, 3), np.uint8)
        cv2.circle(img, (40 + 10 * k, 30), 6, (0, 0, 255), -1)
        cv2.imwrite(str(root / n), img)
    return root


def test_sizes_from_the_images_and_pixels_match_cv2(tmp_path):
    root = _images(tmp_path, ["a.png", "sub/b.png"])
    cv2.imwrite(str(root / "big.png"), np.zeros((100, 200, 3), np.uint8))
    pd.DataFrame(
        {
            "image": ["a.png", "sub/b.png", "big.png"],
            "pitch": 0.0,
            "yaw": 0.0,
            "roll": 0.0,
            "bbox_x": 10.0,
            "bbox_y": 10.0,
            "bbox_w": 20.0,
            "bbox_h": 20.0,
        }
    ).to_csv(tmp_path / "in.csv", index=False)
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "o.csv",
        "--rotate",
        90,
        "--images",
        root,
        "--out-images",
        tmp_path / "out",
    )
    assert res.exit_code == 0, res.output
    for n in ("a.png", "sub/b.png"):
        assert np.array_equal(
            cv2.imread(str(tmp_path / "out" / n)), cv2_transform(cv2.imread(str(root / n)), ("rotate", 90.0))
        )
    o = pd.read_csv(tmp_path / "o.csv")
    # 90 degrees about ((W-1)/2, (H-1)/2) of each image's own size: 160x120 and 200x100 move the box differently
    assert o["bbox_x"].tolist()[:2] == [10.0 + 20, 10.0 + 20] and o["bbox_x"].tolist()[2] != o["bbox_x"].tolist()[0]
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "o2.csv",
        "--rotate",
        90,
        "--images",
        root,
        "--out-images",
        tmp_path / "out2",
        "--image-size",
        W,
        H,
    )
    assert res.exit_code == 1 and "line 4: image size: the image is 200x100, --image-size says 160x120" in res.output


def test_commit_failing_halfway_places_nothing(tmp_path):
    """One target name is an existing folder: the commit fails, and no image (nor the table) is placed."""
    root = _images(tmp_path, ["a.png", "b.png", "c.png"])
    pd.DataFrame({"image": ["a.png", "b.png", "c.png"], "pitch": 0.0, "yaw": 0.0, "roll": 0.0}).to_csv(
        tmp_path / "in.csv", index=False
    )
    out = tmp_path / "out"
    (out / "c.png").mkdir(parents=True)  # sorts last: a.png and b.png would be placed before it fails
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "o.csv",
        "--hflip",
        "--images",
        root,
        "--out-images",
        out,
        "--image-size",
        W,
        H,
        "--overwrite",
    )
    assert res.exit_code == 1 and "c.png" in res.output and "folder" in res.output
    assert sorted(os.listdir(out)) == ["c.png"] and not (tmp_path / "o.csv").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staged leftovers


def test_two_rows_one_output_image(tmp_path):
    root = _images(tmp_path, ["a.png", "x/a.png"])
    pd.DataFrame(
        {"image": ["a.png", "a.png", str(root / "x" / "a.png")], "pitch": 0.0, "yaw": 0.0, "roll": 0.0}
    ).to_csv(tmp_path / "in.csv", index=False)
    # two faces of one picture: transformed once; an absolute name whose base name is taken: an error naming both
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "o.csv",
        "--hflip",
        "--images",
        root,
        "--out-images",
        tmp_path / "out",
        "--image-size",
        W,
        H,
    )
    assert res.exit_code == 1 and "line 4" in res.output and "line 2" in res.output
    assert not (tmp_path / "out").exists() and not (tmp_path / "o.csv").exists()
    pd.DataFrame({"image": ["a.png", "a.png"], "pitch": 0.0, "yaw": 0.0, "roll": [0.0, 5.0]}).to_csv(
        tmp_path / "in2.csv", index=False
    )
    res = hpe(
        "augment",
        tmp_path / "in2.csv",
        "-o",
        tmp_path / "o.csv",
        "--hflip",
        "--images",
        root,
        "--out-images",
        tmp_path / "out",
    )
    assert res.exit_code == 0 and os.listdir(tmp_path / "out") == ["a.png"]


def test_commit_failing_after_some_images_were_placed_undoes_them(tmp_path, monkeypatch):
    """The commit itself fails at the third image (after two were moved into place): both are taken back."""
    import errno

    from hpe_cli.io import transaction

    root = _images(tmp_path, ["a.png", "b.png", "c.png"])
    pd.DataFrame({"image": ["a.png", "b.png", "c.png"], "pitch": 0.0, "yaw": 0.0, "roll": 0.0}).to_csv(
        tmp_path / "in.csv", index=False
    )
    real, calls = transaction.place_file, []

    def place(src, dst, *a):
        calls.append(dst.name)
        if dst.name == "c.png":
            exc = OSError(errno.EIO, "injected I/O error")
            exc.hpe_target = dst  # as transaction.place_file marks its own errors
            raise exc
        return real(src, dst, *a)

    monkeypatch.setattr(transaction, "place_file", place)
    out = tmp_path / "out"
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "o.csv",
        "--hflip",
        "--images",
        root,
        "--out-images",
        out,
        "--image-size",
        W,
        H,
    )
    assert "a.png" in calls and "b.png" in calls and "c.png" in calls
    assert res.exit_code == 1 and "c.png: cannot write: input/output error" in res.output
    assert not out.exists() or os.listdir(out) == []
    assert not (tmp_path / "o.csv").exists()


class _Bar:
    def __init__(self):
        self.total, self.n, self.steps = None, 0, []

    def update(self, k):
        self.n += k
        self.steps.append(k)

    def refresh(self):
        pass


def test_progress_bars_have_totals_and_move_per_image(tmp_path):
    from hpe_cli.pipelines.augment import AugmentOptions, run_augment
    from hpe_cli.pipelines.draw import DrawOptions, run_draw
    from hpe_cli.rotation import get_system

    root = _images(tmp_path, ["a.png", "b.png", "c.png"])
    pd.DataFrame({"image": ["a.png", "b.png", "c.png", "a.png"], "pitch": 0.0, "yaw": 0.0, "roll": 0.0}).to_parquet(
        tmp_path / "in.parquet"
    )
    bar = _Bar()
    opts = AugmentOptions(
        "hflip", system=get_system("300w_lp"), image_size=(W, H), images_dir=root, out_images=tmp_path / "out"
    )
    run_augment(tmp_path / "in.parquet", tmp_path / "o.parquet", opts, bar=bar)
    assert bar.total == 4 and bar.n == 4 and bar.steps.count(1) >= 4  # one step per row's image
    bar = _Bar()
    run_draw(
        tmp_path / "in.parquet",
        tmp_path / "drawn",
        DrawOptions(images=root, system=get_system("300w_lp")),
        progress=bar,
    )
    assert bar.total == 3 and bar.n == 3  # three images (two rows on a.png)


def test_images_alone_give_the_sizes(tmp_path):
    root = _images(tmp_path, ["a.png"])
    pd.DataFrame(
        {
            "image": ["a.png"],
            "pitch": 0.0,
            "yaw": 0.0,
            "roll": 0.0,
            "bbox_x": 10.0,
            "bbox_y": 5.0,
            "bbox_w": 20.0,
            "bbox_h": 20.0,
        }
    ).to_csv(tmp_path / "in.csv", index=False)
    res = hpe("augment", tmp_path / "in.csv", "-o", tmp_path / "o.csv", "--hflip", "--images", root)
    assert res.exit_code == 0, res.output
    assert pd.read_csv(tmp_path / "o.csv")["bbox_x"].tolist() == [W - 1 - 10.0 - 20.0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imgs", "in.csv", "o.csv"]
