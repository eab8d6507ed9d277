"""``hpe augment`` end to end: tables, physics of the written labels, images to the pixel, errors."""

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from conftest import canonical_A, hpe, locate_dots
from hpe_cli.geometry.landmark_schemes import SCHEMES
from hpe_cli.io import BBOX_COLS, LABEL_COLS, MATRIX_COLS, landmark_cols
from hpe_cli.rotation import get_system

DATA = Path(__file__).resolve().parents[2] / "hpe_cli" / "data"
W, H = 640, 480
SCALE = 8.0


def face68():
    """The 68-point mean face (canonical frame), exactly symmetric under the ibug68 permutation."""
    P = np.load(DATA / "reference_3d_68_points_trans.npy").astype(float) * [1, -1, -1]
    P = P - P.mean(axis=0) * [1, 0, 0]
    return (P + (P * [-1, 1, 1])[SCHEMES["ibug68"]]) / 2 * 10.0


FACE = face68()


def project(A, centre):
    """Orthographic image (u right, v down) of FACE under canonical labels A (N, 3, 3), centres (N, 2)."""
    X = np.einsum("nij,kj->nki", A, FACE) * SCALE
    return np.stack([centre[:, None, 0] + X[..., 0], centre[:, None, 1] - X[..., 1]], axis=-1)


def make_table(n=40, seed=0):
    rng = np.random.default_rng(seed)
    pyr = rng.uniform(-180, 180, (n, 3))
    pyr[:, 1] = rng.uniform(-89, 89, n)  # 300W-LP primary solution
    centre = rng.uniform(200, 400, (n, 2))
    lm = project(canonical_A(pyr), centre)
    lo, hi = lm.min(axis=1), lm.max(axis=1)
    df = pd.DataFrame(
        {
            "id": [f"s{i:03d}" for i in range(n)],
            "subject": np.arange(n) % 7,
            "pitch": pyr[:, 0],
            "yaw": pyr[:, 1],
            "roll": pyr[:, 2],
            "cx": centre[:, 0],
            "cy": centre[:, 1],
        }
    )
    flat = lm.reshape(n, -1)
    df = pd.concat([df, pd.DataFrame(flat, columns=landmark_cols(68))], axis=1)
    for c, v in zip(BBOX_COLS, [lo[:, 0] - 5, lo[:, 1] - 5, hi[:, 0] - lo[:, 0] + 10, hi[:, 1] - lo[:, 1] + 10]):
        df[c] = v
    df["note"] = "keep me"
    return df


def lms(df, n=68):
    return df[landmark_cols(n)].to_numpy().reshape(len(df), n, 2)


def moved_centre(op_matrix_pixels, centre):
    return centre @ op_matrix_pixels[:, :2].T + op_matrix_pixels[:, 2]


def pixel_map(kind, angle=None):
    """The expected pixel map, written out by hand (pixel centres at integers)."""
    cx, cy = (W - 1) / 2, (H - 1) / 2
    if kind == "hflip":
        return np.array([[-1.0, 0, W - 1], [0, 1, 0]])
    if kind == "vflip":
        return np.array([[1.0, 0, 0], [0, -1, H - 1]])
    if kind == "both":
        return np.array([[-1.0, 0, W - 1], [0, -1, H - 1]])
    return cv2.getRotationMatrix2D((cx, cy), angle, 1.0)


@pytest.mark.parametrize(
    "args,kind,angle",
    [
        (["--hflip"], "hflip", None),
        (["--vflip"], "vflip", None),
        (["--hflip", "--vflip"], "both", None),
        (["--rotate", "-37.5"], "rotate", -37.5),
        (["--rotate", "200"], "rotate", 200.0),
    ],
)
def test_written_labels_reproduce_the_written_landmarks(tmp_path, args, kind, angle):
    """Physical: the face projected with the OUTPUT angles lands on the OUTPUT landmarks, for every row."""
    df = make_table()
    src = tmp_path / "in.csv"
    df.to_csv(src, index=False)
    digest = hashlib.sha256(src.read_bytes()).hexdigest()
    out = tmp_path / "out.parquet"
    res = hpe("augment", src, "-o", out, "--image-size", W, H, *args)
    assert res.exit_code == 0, res.output
    assert hashlib.sha256(src.read_bytes()).hexdigest() == digest  # input untouched
    o = pd.read_parquet(out)
    assert len(o) == len(df)
    P = pixel_map(kind, angle)
    centre = moved_centre(P, df[["cx", "cy"]].to_numpy())
    A2 = canonical_A(o[["pitch", "yaw", "roll"]].to_numpy())
    np.testing.assert_allclose(lms(o), project(A2, centre), atol=1e-6)
    A2b = canonical_A(o[["pitch_2", "yaw_2", "roll_2"]].to_numpy())
    np.testing.assert_allclose(A2b, A2, atol=1e-9)
    np.testing.assert_allclose(o[MATRIX_COLS].to_numpy().reshape(-1, 3, 3), A2, atol=1e-9)
    # pass-through columns, column order
    for c in ("id", "subject", "cx", "cy", "note"):
        assert o[c].tolist() == df[c].tolist()
    assert list(o.columns[: len(df.columns)]) == list(df.columns)
    assert list(o.columns[len(df.columns) :]) == [c for c in LABEL_COLS if c not in df.columns]
    meta = pq.read_schema(out).metadata
    assert meta[b"hpe:system"] == b"300w_lp"
    assert json.loads(meta[b"hpe:augment"])["image_size"] == [W, H]


def test_boxes_follow_the_rule(tmp_path):
    df = make_table(10)
    df.to_parquet(tmp_path / "in.parquet")
    assert (
        hpe("augment", tmp_path / "in.parquet", "-o", tmp_path / "f.parquet", "--image-size", W, H, "--hflip").exit_code
        == 0
    )
    f = pd.read_parquet(tmp_path / "f.parquet")
    # a flip moves the box exactly (margins kept)
    np.testing.assert_allclose(f["bbox_x"], W - 1 - df["bbox_x"] - df["bbox_w"], atol=1e-9)
    np.testing.assert_allclose(f[["bbox_y", "bbox_w", "bbox_h"]], df[["bbox_y", "bbox_w", "bbox_h"]], atol=1e-9)
    res = hpe("augment", tmp_path / "in.parquet", "-o", tmp_path / "r.parquet", "--image-size", W, H, "--rotate", 33)
    assert res.exit_code == 0
    r = pd.read_parquet(tmp_path / "r.parquet")
    lm = lms(r)
    np.testing.assert_allclose(r["bbox_x"], lm[..., 0].min(axis=1), atol=1e-9)
    np.testing.assert_allclose(r["bbox_h"], lm[..., 1].max(axis=1) - lm[..., 1].min(axis=1), atol=1e-9)
    assert (
        hpe(
            "augment",
            tmp_path / "in.parquet",
            "-o",
            tmp_path / "c.parquet",
            "--image-size",
            300,
            300,
            "--rotate",
            33,
            "--clip",
        ).exit_code
        == 0
    )
    c = pd.read_parquet(tmp_path / "c.parquet")
    assert (c["bbox_x"] >= 0).all() and (c["bbox_x"] + c["bbox_w"] <= 299 + 1e-9).all()


def test_spec_examples_through_the_cli(tmp_path):
    pd.DataFrame({"pitch": [20.0, 0.0], "yaw": [-50.0, 0.0], "roll": [15.0, 0.0]}).to_csv(
        tmp_path / "a.csv", index=False
    )
    assert (
        hpe("augment", tmp_path / "a.csv", "-o", tmp_path / "r.csv", "--image-size", 450, 450, "--rotate", 30).exit_code
        == 0
    )
    r = pd.read_csv(tmp_path / "r.csv")
    np.testing.assert_allclose(r.loc[0, ["pitch", "yaw", "roll"]].astype(float), [43.511, -33.607, -19.343], atol=5e-4)
    assert (
        hpe("augment", tmp_path / "a.csv", "-o", tmp_path / "v.csv", "--image-size", 450, 450, "--vflip").exit_code == 0
    )
    v = pd.read_csv(tmp_path / "v.csv")
    np.testing.assert_allclose(v.loc[1, ["pitch", "yaw", "roll"]].astype(float), [0, 0, 180], atol=1e-9)


def test_matrix_only_input_in_another_system(tmp_path):
    sysm = get_system("6drepnet")
    rng = np.random.default_rng(5)
    pyr = rng.uniform(-80, 80, (12, 3))
    R = sysm.from_angles(pyr)
    pd.DataFrame(R.reshape(-1, 9), columns=MATRIX_COLS).to_parquet(tmp_path / "m.parquet")
    res = hpe(
        "augment",
        tmp_path / "m.parquet",
        "-o",
        tmp_path / "o.parquet",
        "--system",
        "6drepnet",
        "--image-size",
        W,
        H,
        "--mirror-line",
        25,
    )
    assert res.exit_code == 0, res.output
    o = pd.read_parquet(tmp_path / "o.parquet")
    assert all(c in o.columns for c in LABEL_COLS)
    A = sysm.to_canonical(R)
    A2 = sysm.to_canonical(sysm.from_angles(o[["pitch", "yaw", "roll"]].to_numpy()))
    np.testing.assert_allclose(o[MATRIX_COLS].to_numpy().reshape(-1, 3, 3), sysm.from_canonical(A2), atol=1e-9)
    # mirror about L_25: reflect the projected face in 2-D, re-index, compare with the projection of A2
    c = np.full((12, 2), 320.0)
    t = np.deg2rad(50)
    Ry = np.array([[np.cos(t), np.sin(t)], [np.sin(t), -np.cos(t)]])  # y-up reflection
    F = np.diag([1.0, -1.0])
    ctr = np.array([(W - 1) / 2, (H - 1) / 2])
    moved = (project(A, c) - ctr) @ (F @ Ry @ F).T + ctr
    new_c = (c - ctr) @ (F @ Ry @ F).T + ctr
    np.testing.assert_allclose(moved[:, SCHEMES["ibug68"]], project(A2, new_c), atol=1e-6)


def _dots_image(pts, w, h, sigma=1.6):
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    img = np.zeros((h, w))
    for x, y in pts:
        img += np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma**2))
    g = np.clip(img * 250, 0, 255).astype(np.uint8)
    return np.dstack([g, g // 2, 255 - g])  # 3 channels, BGR


@pytest.mark.parametrize("args", [["--mirror-line", "30"], ["--rotate", "-20"], ["--hflip"], ["--vflip"]])
def test_images_agree_with_landmarks_to_the_pixel(tmp_path, args):
    w, h = 161, 120  # odd/even sizes expose any half-pixel centre error
    rng = np.random.default_rng(11)
    grid = np.array([(x, y) for x in (45, 62, 80, 98, 116) for y in (42, 60, 78)], float)[:15]
    rows = []
    (tmp_path / "imgs" / "sub").mkdir(parents=True)
    for i in range(3):
        pts = np.vstack([grid + rng.uniform(-2, 2, grid.shape), rng.uniform(50, 110, (6, 2)) * [1, 0] + [0, 96]])
        pts[15:, 0] = 40 + 16 * np.arange(6) + rng.uniform(-2, 2, 6)  # 21 well-separated points
        name = f"sub/im{i}.png"
        cv2.imwrite(str(tmp_path / "imgs" / name), _dots_image(pts, w, h))
        rows.append(
            {
                "image": name,
                "pitch": 10.0 * i,
                "yaw": -20.0,
                "roll": 5.0,
                **{c: v for c, v in zip(landmark_cols(21), pts.reshape(-1))},
            }
        )
    rows.append(dict(rows[0]))  # a second face in the same image: the image is written once
    pd.DataFrame(rows).to_csv(tmp_path / "in.csv", index=False)
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "out.csv",
        "--image-size",
        w,
        h,
        *args,
        "--images",
        tmp_path / "imgs",
        "--out-images",
        tmp_path / "aug",
    )
    assert res.exit_code == 0, res.output
    assert "images: 3 written" in res.output
    o = pd.read_csv(tmp_path / "out.csv")
    for i in range(3):
        img = cv2.imread(str(tmp_path / "aug" / o.loc[i, "image"]), cv2.IMREAD_UNCHANGED)
        assert img.shape == (h, w, 3)
        pts = lms(o.iloc[[i]], 21)[0]
        inside = ((pts >= 9) & (pts <= np.array([w, h]) - 10)).all(axis=1)
        assert inside.sum() >= 12
        found = locate_dots(img[..., 0], pts[inside])
        assert np.abs(found - pts[inside]).max() < 0.05
    assert not any(p.name.startswith(".hpe-augment") for p in (tmp_path / "aug").iterdir())
    # --overwrite is needed a second time
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "out2.csv",
        "--image-size",
        w,
        h,
        *args,
        "--images",
        tmp_path / "imgs",
        "--out-images",
        tmp_path / "aug",
    )
    assert res.exit_code == 1 and "already exists" in res.output
    assert not (tmp_path / "out2.csv").exists()


def test_real_aflw2000_hflip_with_images(tmp_path, realdata):
    from hpe_cli.datasets.mat import read_mat_dir

    src = realdata / "aflw2000_prnet"
    res = hpe(
        "augment",
        src,
        "-o",
        tmp_path / "f.parquet",
        "--image-size",
        450,
        450,
        "--hflip",
        "--images",
        src,
        "--out-images",
        tmp_path / "img",
    )
    assert res.exit_code == 0, res.output
    f = pd.read_parquet(tmp_path / "f.parquet")
    d = read_mat_dir(src)
    np.testing.assert_allclose(f[["pitch", "yaw", "roll"]], d[["pitch", "yaw", "roll"]] * [1, -1, -1], atol=1e-9)
    a = cv2.imread(str(src / "image00050.jpg"))
    b = cv2.imread(str(tmp_path / "img" / "image00050.jpg"))
    assert np.abs(b.astype(float) - cv2.flip(a, 1)).mean() < 2.0  # only JPEG re-encoding differs
    # the 21 AFLW points (NaN = invisible) mirrored and re-indexed
    lm = read_mat_dir(src, landmarks=True)
    lm = lm[["file", "pitch", "yaw", "roll"] + landmark_cols(21)]
    lm.to_parquet(tmp_path / "lm.parquet")
    res = hpe("augment", tmp_path / "lm.parquet", "-o", tmp_path / "lmf.parquet", "--image-size", 450, 450, "--hflip")
    assert res.exit_code == 0, res.output
    assert "scheme aflw21" in res.output
    got = lms(pd.read_parquet(tmp_path / "lmf.parquet"), 21)
    want = lms(lm, 21)[:, SCHEMES["aflw21"]] * [-1, 1] + [449, 0]
    np.testing.assert_allclose(got, want, atol=1e-9)
    assert np.isnan(got).any()


def test_landmarks_none_and_rejects(tmp_path):
    df = make_table(6)
    df.loc[1, "pitch"] = np.nan
    df.to_csv(tmp_path / "in.csv", index=False)
    res = hpe(
        "augment",
        tmp_path / "in.csv",
        "-o",
        tmp_path / "o.csv",
        "--image-size",
        W,
        H,
        "--vflip",
        "--landmarks",
        "none",
        "--rejects",
        tmp_path / "rej.csv",
    )
    assert res.exit_code == 0, res.output
    o = pd.read_csv(tmp_path / "o.csv")
    assert len(o) == 5
    np.testing.assert_allclose(lms(o), lms(df.drop(index=1)), atol=1e-9)  # left unchanged
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert rej["id"].tolist() == ["s001"] and rej["reason"].tolist() == ["missing value in pitch"]
    assert "rejected: 1 missing value in pitch" in res.output


def test_matrix_checks(tmp_path):
    A = canonical_A([[10.0, 20.0, 30.0]] * 3)
    df = pd.DataFrame(A.reshape(-1, 9), columns=MATRIX_COLS)
    df[["pitch", "yaw", "roll"]] = [10.0, 20.0, 30.0]
    df.loc[1, "r00"] = 3.0  # not a rotation
    df.loc[2, "yaw"] = 25.0  # angles and matrix disagree
    df.to_parquet(tmp_path / "in.parquet")
    res = hpe(
        "augment",
        tmp_path / "in.parquet",
        "-o",
        tmp_path / "o.parquet",
        "--image-size",
        W,
        H,
        "--rotate",
        10,
        "--rejects",
        tmp_path / "rej.parquet",
    )
    assert res.exit_code == 0, res.output
    assert len(pd.read_parquet(tmp_path / "o.parquet")) == 1
    reasons = sorted(pd.read_parquet(tmp_path / "rej.parquet")["reason"])
    assert reasons == ["angles and r00..r22 disagree", "not a rotation: not orthonormal"]


@pytest.mark.parametrize(
    "args,code,msg",
    [
        ([], 2, "expected one of --hflip"),
        (["--hflip", "--rotate", "3"], 2, "expected one augmentation"),
        (["--rotate", "nan"], 2, "finite"),
        (["--hflip", "--out-images", "o"], 2, "--out-images needs --images"),
        (["--hflip", "--landmarks", "aflw21"], 1, "--landmarks aflw21 expects 21"),
    ],
)
def test_usage_and_input_errors(tmp_path, args, code, msg):
    make_table(3).to_csv(tmp_path / "in.csv", index=False)
    res = hpe("augment", tmp_path / "in.csv", "-o", tmp_path / "o.csv", "--image-size", W, H, *args)
    assert res.exit_code == code, res.output
    assert msg in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "o.csv").exists()


def test_table_errors(tmp_path):
    pd.DataFrame({"a": [1.0]}).to_csv(tmp_path / "bad.csv", index=False)
    res = hpe("augment", tmp_path / "bad.csv", "-o", tmp_path / "o.csv", "--image-size", W, H, "--hflip")
    assert res.exit_code == 1 and "expected angle columns pitch,yaw,roll" in res.output
    # text in a number column rejects that row only
    t = pd.DataFrame(
        {"pitch": ["1", "abc"], "yaw": [2.0, 2.0], "roll": [3.0, 3.0], "lm0_x": ["1", "x"], "lm0_y": [1.0, np.nan]}
    )
    t.to_csv(tmp_path / "text.csv", index=False)
    # without --rejects a bad row fails the run, naming the file line (header = line 1), as in every command
    res = hpe("augment", tmp_path / "text.csv", "-o", tmp_path / "t.csv", "--image-size", W, H, "--rotate", 5)
    assert res.exit_code == 1, res.output
    assert "text.csv: line 3: non-numeric value in pitch; 1 row(s) cannot be used" in res.output
    assert not (tmp_path / "t.csv").exists()
    res = hpe(
        "augment",
        tmp_path / "text.csv",
        "-o",
        tmp_path / "t.csv",
        "--image-size",
        W,
        H,
        "--rotate",
        5,
        "--rejects",
        tmp_path / "r.csv",
    )
    assert res.exit_code == 0, res.output
    assert "1 of 2 rows" in res.output and "non-numeric value in pitch" in res.output
    assert pd.read_csv(tmp_path / "r.csv")["row"].tolist() == [3]
    t["pitch"] = ["1", "2"]
    t.to_csv(tmp_path / "text.csv", index=False)
    res = hpe("augment", tmp_path / "text.csv", "-o", tmp_path / "t2.csv", "--image-size", W, H, "--rotate", 5)
    assert res.exit_code == 1 and "line 3: non-numeric value in lm0_x" in res.output
    res = hpe(
        "augment",
        tmp_path / "text.csv",
        "-o",
        tmp_path / "t2.csv",
        "--image-size",
        W,
        H,
        "--rotate",
        5,
        "--rejects",
        tmp_path / "r2.csv",
        "--strict",
    )
    assert res.exit_code == 1 and "--strict" in res.output and not (tmp_path / "t2.csv").exists()
    df = make_table(2)[["pitch", "yaw", "roll"] + landmark_cols(5)]
    df.to_csv(tmp_path / "five.csv", index=False)
    res = hpe("augment", tmp_path / "five.csv", "-o", tmp_path / "o.csv", "--image-size", W, H, "--hflip")
    assert res.exit_code == 1 and "match no built-in scheme" in res.output
    assert (
        hpe("augment", tmp_path / "five.csv", "-o", tmp_path / "o.csv", "--image-size", W, H, "--rotate", 5).exit_code
        == 0
    )
    res = hpe("augment", tmp_path / "five.csv", "-o", tmp_path / "o.csv", "--image-size", W, H, "--rotate", 5)
    assert res.exit_code == 1 and "already exists" in res.output
    assert (
        hpe(
            "augment",
            tmp_path / "five.csv",
            "-o",
            tmp_path / "o.csv",
            "--image-size",
            W,
            H,
            "--rotate",
            5,
            "--overwrite",
        ).exit_code
        == 0
    )


def test_image_errors_leave_nothing_behind(tmp_path):
    (tmp_path / "imgs").mkdir()
    cv2.imwrite(str(tmp_path / "imgs" / "a.png"), np.zeros((20, 30, 3), np.uint8))
    pd.DataFrame({"image": ["a.png", "missing.png"], "pitch": [0.0, 0], "yaw": [0.0, 0], "roll": [0.0, 0]}).to_csv(
        tmp_path / "in.csv", index=False
    )
    base = [tmp_path / "in.csv", "-o", tmp_path / "o.csv", "--hflip", "--images", tmp_path / "imgs"]
    res = hpe("augment", *base, "--image-size", 30, 20, "--out-images", tmp_path / "out")
    assert res.exit_code == 1 and "line 3: image not found" in res.output and "missing.png" in res.output
    assert not (tmp_path / "o.csv").exists() and not (tmp_path / "out").exists()
    res = hpe("augment", *base, "--image-size", 31, 20, "--out-images", tmp_path / "out")
    assert res.exit_code == 1 and "the image is 30x20, --image-size says 31x20" in res.output
    res = hpe("augment", *base, "--image-size", 30, 20, "--out-images", tmp_path / "imgs")
    assert res.exit_code == 1 and "must differ from --images" in res.output
    assert not (tmp_path / "o.csv").exists()
    assert sorted(p.name for p in (tmp_path / "imgs").iterdir()) == ["a.png"]


def test_help_has_examples():
    res = hpe("augment", "--help")
    assert res.exit_code == 0
    assert "Examples:" in res.output and "hpe augment labels.parquet" in res.output


def test_threaded_pipeline_same_output_and_rejects(tmp_path):
    """Two worker threads and small batches give exactly the one-thread output and rejects, in order."""
    from hpe_cli.pipelines.augment import AugmentOptions, run_augment
    from hpe_cli.rotation import get_system

    df = make_table(50)
    df.loc[[3, 17, 41], "pitch"] = np.nan
    src = tmp_path / "in.parquet"
    df.to_parquet(src)
    outs = []
    for workers, bs in ((1, 1000), (2, 7)):
        out, rej = tmp_path / f"o{workers}.parquet", tmp_path / f"r{workers}.csv"
        opts = AugmentOptions(
            "rotate", 20.0, system=get_system("300w_lp"), image_size=(W, H), rejects=rej, batch_size=bs, threads=workers
        )
        s = run_augment(src, out, opts)
        assert s["rows"] == 50 and s["written"] == 47
        outs.append((pd.read_parquet(out), pd.read_csv(rej)))
    pd.testing.assert_frame_equal(outs[0][0], outs[1][0])
    pd.testing.assert_frame_equal(outs[0][1], outs[1][1])
    assert outs[1][1]["row"].tolist() == [4, 18, 42]  # 1-based Parquet rows
