"""evaluate -> draw --worst on the real AFLW2000 sample and the golden predictions.

Oracles: the geodesic ranking against SciPy, and the pixels: each prediction line ends in a dot of its axis
colour where SciPy's matrix puts it (centre and length from the .mat Pose_Para read with scipy.io).
"""

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import scipy.io

from conftest import hpe

from .conftest import COLOURS, GOLDEN, a300wlp, geodesic_deg


def test_evaluate_then_draw_worst(realdata, errors, tmp_path):
    aflw = realdata / "aflw2000_prnet"
    out = tmp_path / "worst"
    res = hpe("draw", errors, "-o", out, "--images", aflw, "--worst", "5", "--thickness", "2")
    assert res.exit_code == 0, res.output
    assert "300w_lp (file metadata)" in res.output
    gt = pd.read_csv(GOLDEN / "gt.csv").set_index("image")
    pred = pd.read_csv(GOLDEN / "pred.csv").set_index("image")
    geo = pd.Series({k: geodesic_deg(a300wlp(*gt.loc[k]), a300wlp(*pred.loc[k])) for k in gt.index})
    want = geo.sort_values(ascending=False).index[:5]
    files = sorted(p.name for p in out.iterdir())
    assert files == [f"{k + 1:04d}_{Path(n).stem}.png" for k, n in enumerate(want)]
    for k, name in enumerate(want):
        img = cv2.imread(str(out / files[k]))
        m = scipy.io.loadmat(str(aflw / name))
        pose = m["Pose_Para"].reshape(-1)
        H, W = img.shape[:2]
        assert (H, W) == cv2.imread(str(aflw / name.replace(".mat", ".jpg"))).shape[:2]
        c = np.array([pose[3], H - 1 - pose[4]])
        L = abs(pose[6]) * 100_000
        P = a300wlp(*pred.loc[name])
        # canonical x = the subject's left, y = up, z = out of the face; the lines are x, -y (forehead to chin)
        # and z, in image (u right, v down) coordinates: direction s * (A[0, i], -A[1, i]), s = (1, -1, 1)
        ends = [c + L * s * np.array([P[0, i], -P[1, i]]) for i, s in enumerate((1, -1, 1))]
        for i in range(3):
            e = ends[i]
            if not (4 <= e[0] < W - 4 and 4 <= e[1] < H - 4):
                continue
            if any(np.hypot(*(e - ends[j])) < 8 for j in range(3) if j != i):
                continue  # two dots on top of each other
            px = img[round(e[1]), round(e[0])].astype(int)
            assert np.abs(px - COLOURS[i]).max() < 60, (name, i, px)
        # the legend (dark box, top-left) and the error (top-right) are there
        assert img[2:20, 2:20].mean() < 120


def test_draw_worst_api_and_bad_sort_column(realdata, errors, tmp_path):
    from hpe_cli.pipelines.draw import draw_worst

    got = draw_worst(errors, images=realdata / "aflw2000_prnet", out_dir=tmp_path / "api", worst=3, sort_by="err_pitch")
    t = pd.read_parquet(errors)
    want = t.sort_values("err_pitch", ascending=False)["image"].tolist()[:3]
    assert [k for k, _, _ in got] == [(w,) for w in want]
    assert all(p.is_file() and p.parent == tmp_path / "api" for _, p, _ in got)
    assert "err_pitch" in got[0][2] and want[0] in got[0][2]
    res = hpe("draw", errors, "-o", tmp_path / "x", "--images", realdata / "aflw2000_prnet", "--sort-by", "nope")
    assert res.exit_code == 1 and "--sort-by 'nope'" in res.output and len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()
    res = hpe("draw", errors, "-o", tmp_path / "y", "--images", tmp_path)
    assert res.exit_code == 1 and "image not found" in res.output and not (tmp_path / "y").exists()
