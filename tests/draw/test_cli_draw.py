"""``hpe draw`` end to end (CliRunner), on canvases, synthetic images and the real AFLW2000 files."""

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.rotation import get_system

REALDATA = Path(__file__).resolve().parents[3] / "shared" / "realdata"
AFLW = REALDATA / "aflw2000_prnet"
RED, GREEN, BLUE, WHITE = (0, 0, 255), (0, 255, 0), (255, 0, 0), (255, 255, 255)


def px(img, u, v):
    return tuple(int(x) for x in img[int(v), int(u)])


def test_canvas_colours_and_names(tmp_path):
    t = tmp_path / "poses.csv"
    pd.DataFrame(
        {
            "image": ["a.png", "b.png"],
            "tdx": [100, 100],
            "tdy": [100, 100],
            "size": [80, 80],
            "pitch": [0.0, 0.0],
            "yaw": [0.0, 89.999],
            "roll": [0.0, 0.0],
        }
    ).to_csv(t, index=False)
    res = hpe("draw", t, "-o", tmp_path / "out", "--canvas", "200x200", "--thickness", "5")
    assert res.exit_code == 0, res.output
    a = cv2.imread(str(tmp_path / "out" / "a.png"))
    assert a.shape == (200, 200, 3)
    assert px(a, 160, 100) == RED and px(a, 100, 160) == GREEN and px(a, 100, 40) == WHITE
    b = cv2.imread(str(tmp_path / "out" / "b.png"))
    assert px(b, 40, 100) == BLUE  # yaw +90: the nose points to the image left


def _images(tmp_path):
    root = tmp_path / "imgs"
    (root / "sub").mkdir(parents=True)
    cv2.imwrite(str(root / "sub" / "a.png"), np.full((120, 160, 3), 128, np.uint8))
    return root


def test_bbox_centre_relative_names_and_inputs_untouched(tmp_path):
    root = _images(tmp_path)
    before = (root / "sub" / "a.png").read_bytes()
    t = tmp_path / "l.parquet"
    pd.DataFrame(
        {
            "image": ["sub/a.png"],
            "bbox_x": [40.0],
            "bbox_y": [20.0],
            "bbox_w": [80.0],
            "bbox_h": [80.0],
            "pitch": [0.0],
            "yaw": [0.0],
            "roll": [0.0],
        }
    ).to_parquet(t)
    out = tmp_path / "drawn"
    res = hpe("draw", t, "-o", out, "--images", root, "--thickness", "5")
    assert res.exit_code == 0, res.output
    img = cv2.imread(str(out / "sub" / "a.png"))
    # centre (80, 60), length bbox_h / 2 = 40
    assert px(img, 100, 60) == RED and px(img, 80, 80) == GREEN and px(img, 60, 60) == (128, 128, 128)
    assert (root / "sub" / "a.png").read_bytes() == before
    res = hpe("draw", t, "-o", out, "--images", root)
    assert res.exit_code == 1 and "--overwrite" in res.output
    res = hpe("draw", t, "-o", root, "--images", root, "--overwrite")
    assert res.exit_code == 1 and "must differ from --images" in res.output
    assert (root / "sub" / "a.png").read_bytes() == before


def test_missing_image_error_and_rejects(tmp_path):
    root = _images(tmp_path)
    t = tmp_path / "l.csv"
    pd.DataFrame({"image": ["sub/a.png", "nope.png"], "pitch": 0, "yaw": 0, "roll": 0}).to_csv(t, index=False)
    res = hpe("draw", t, "-o", tmp_path / "o1", "--images", root)
    assert res.exit_code == 1 and "l.csv: line 3: image not found" in res.output and "nope.png" in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "o1" / "sub" / "a.png").exists()  # nothing drawn before the check
    rej = tmp_path / "rej.csv"
    res = hpe("draw", t, "-o", tmp_path / "o2", "--images", root, "--rejects", rej)
    assert res.exit_code == 0
    assert (tmp_path / "o2" / "sub" / "a.png").exists()
    assert pd.read_csv(rej)["row"].tolist() == [3]  # the CSV line (header = line 1)
    (root / "broken.png").write_bytes(b"not an image")
    pd.DataFrame({"image": ["broken.png", "sub/a.png"], "pitch": 0, "yaw": 0, "roll": 0}).to_csv(t, index=False)
    res = hpe("draw", t, "-o", tmp_path / "o3", "--images", root)
    assert res.exit_code == 1 and "not a readable image" in res.output
    res = hpe("draw", t, "-o", tmp_path / "o4", "--images", root, "--rejects", tmp_path / "rej2.csv")
    assert res.exit_code == 0 and (tmp_path / "o4" / "sub" / "a.png").exists()
    assert pd.read_csv(tmp_path / "rej2.csv")["reason"].str.startswith("not a readable image").all()


def test_matrix_of_another_system_draws_the_same(tmp_path):
    rng = np.random.default_rng(5)
    pyr = np.column_stack([rng.uniform(-60, 60, 4), rng.uniform(-170, 170, 4), rng.uniform(-60, 60, 4)])
    base = pd.DataFrame({"image": [f"{i}.png" for i in range(4)], "tdx": 64.0, "tdy": 64.0, "size": 50.0})
    ang = base.assign(pitch=pyr[:, 0], yaw=pyr[:, 1], roll=pyr[:, 2])
    ang.to_csv(tmp_path / "ang.csv", index=False)
    s6 = get_system("6drepnet")
    G = s6.from_canonical(get_system("whenet").to_canonical(get_system("whenet").from_angles(pyr)))
    mat = pd.concat(
        [base, pd.DataFrame(G.reshape(-1, 9), columns=[f"r{i}{j}" for i in range(3) for j in range(3)])], axis=1
    )
    mat.to_csv(tmp_path / "mat.csv", index=False)
    for style in ("axes", "cube"):
        assert (
            hpe(
                "draw",
                tmp_path / "ang.csv",
                "-o",
                tmp_path / f"a_{style}",
                "--canvas",
                "128x128",
                "--system",
                "whenet",
                "--style",
                style,
                "-q",
            ).exit_code
            == 0
        )
        assert (
            hpe(
                "draw",
                tmp_path / "mat.csv",
                "-o",
                tmp_path / f"m_{style}",
                "--canvas",
                "128x128",
                "--system",
                "6drepnet",
                "--style",
                style,
                "-q",
            ).exit_code
            == 0
        )
        for i in range(4):
            a = cv2.imread(str(tmp_path / f"a_{style}" / f"{i}.png")).astype(int)
            m = cv2.imread(str(tmp_path / f"m_{style}" / f"{i}.png")).astype(int)
            assert np.abs(a - m).max() <= 1  # sub-pixel rounding only


def test_cube_turned_away(tmp_path):
    t = tmp_path / "p.csv"
    pd.DataFrame(
        {
            "image": ["front.png", "back.png"],
            "tdx": 100,
            "tdy": 100,
            "size": 50,
            "pitch": [0, 0],
            "yaw": [0, 180],
            "roll": [0, 0],
        }
    ).to_csv(t, index=False)
    assert (
        hpe(
            "draw",
            t,
            "-o",
            tmp_path / "o",
            "--canvas",
            "200x200",
            "--system",
            "whenet",
            "--style",
            "cube",
            "--thickness",
            "5",
        ).exit_code
        == 0
    )
    front, back = (cv2.imread(str(tmp_path / "o" / n)) for n in ("front.png", "back.png"))
    assert px(front, 100, 50) == GREEN  # the face-front square
    assert px(back, 100, 50) == RED  # seen from behind: the back square hides it


def test_grid(tmp_path):
    t = tmp_path / "p.csv"
    pd.DataFrame(
        {"image": [f"{i}.png" for i in range(5)], "pitch": 0, "yaw": np.linspace(-80, 80, 5), "roll": 0}
    ).to_csv(t, index=False)
    res = hpe(
        "draw", t, "-o", tmp_path / "g", "--canvas", "100x100", "--grid", "--grid-cols", "2", "--tile", "64", "-q"
    )
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in (tmp_path / "g").iterdir())
    assert names == ["contact_sheet_001.png", "contact_sheet_002.png"]
    assert cv2.imread(str(tmp_path / "g" / "contact_sheet_001.png")).shape == (128, 128, 3)


def test_usage_errors(tmp_path):
    t = tmp_path / "p.csv"
    pd.DataFrame({"pitch": [0], "yaw": [0], "roll": [0]}).to_csv(t, index=False)
    res = hpe("draw", t, "-o", tmp_path / "o")
    assert res.exit_code == 1 and "--image-size WxH" in res.output
    assert hpe("draw", t, "-o", tmp_path / "o", "--canvas", "12by3").exit_code == 2
    assert hpe("draw", t, "-o", tmp_path / "o", "--canvas", "64x64", "-q").exit_code == 0
    assert (tmp_path / "o" / "row_000000.png").exists()


@pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")
def test_pose_para_tdy_is_measured_from_the_bottom():
    """pt3d_68 = s * A @ X + t with the image row = H - 1 - y, checked on all 16 AFLW2000 files.

    Mapping each image's 68 fitted landmarks back to model coordinates must give
    nearly the same head for everybody (the nose tip within a few mm, BFM units
    are micrometres) with the bottom-up rows, and scattered points with top-down rows.
    """
    import scipy.io

    A300 = get_system("300w_lp")
    spread = {}
    for flip in (True, False):
        X = []
        for f in sorted(AFLW.glob("*.mat")):
            m = scipy.io.loadmat(f)
            P = m["Pose_Para"].ravel().astype(float)
            p3 = m["pt3d_68"].astype(float)
            H = cv2.imread(str(f.with_suffix(".jpg"))).shape[0]
            A = A300.from_angles(np.rad2deg(P[None, :3]))[0]
            y = H - 1 - p3[1] if flip else p3[1]
            X.append(A.T @ (np.stack([p3[0], y, p3[2]]) - P[3:6, None]) / P[6])
        X = np.array(X)
        spread[flip] = X[:, :, 30].std(axis=0).max()  # nose tip
    assert spread[True] < 3000 < 10000 < spread[False]


@pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")
def test_mat_folder(tmp_path):
    res = hpe("draw", AFLW, "-o", tmp_path / "o", "-q")
    assert res.exit_code == 0, res.output
    assert len(list((tmp_path / "o").glob("*.jpg"))) == 16
    # the centre is (tdx, H - 1 - tdy): image00050 has tdx 229.71, tdy 209.54, H 450, roll 5.6 deg
    res = hpe(
        "draw",
        AFLW / "image00050.mat",
        "-o",
        tmp_path / "c",
        "--canvas",
        "450x450",
        "--length",
        "60",
        "--thickness",
        "7",
        "-q",
    )
    assert res.exit_code == 0, res.output
    img = cv2.imread(str(tmp_path / "c" / "image00050.jpg")).astype(int)
    u, v = 229.71, 449 - 209.54
    b, gch, r = img[int(round(v + 40)), int(round(u - 40 * np.sin(np.deg2rad(5.6))))]
    assert gch > 200 and r < 80 and b < 80  # on the green line, 40 px below the centre
    b, gch, r = img[int(round(v + 40 * np.sin(np.deg2rad(5.6)))), int(round(u + 40))]
    assert r > 200 and gch < 80 and b < 80  # on the red line
    assert img[int(round(209.54)), int(round(u + 40))].min() > 230  # a top-down tdy would put the red line here
