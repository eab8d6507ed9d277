"""Dataset readers as shipped: 300W-LP root/zip/landmarks, DAD-3DHeads, TableSource.system, and the
.mat-is-always-300w_lp fix in draw/augment."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest
import scipy.io
from scipy.spatial.transform import Rotation

from conftest import hpe
from hpe_cli.errors import HpeError
from hpe_cli.io import open_table

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"
W300 = REAL / "300wlp_face3d" / "IBUG_image_008_1_0.mat"
AFLW = REAL / "aflw2000_prnet"


def table(path, **kw):
    src = open_table(path, **kw)
    return src, pa.Table.from_batches(list(src.batches()), schema=src.schema).to_pandas()


# ------------------------------------------------------------------------------------------------ 300W-LP
@pytest.fixture
def w300_root(tmp_path):
    if not W300.exists():
        pytest.skip("real 300W-LP sample absent")
    root = tmp_path / "300W_LP"
    (root / "IBUG").mkdir(parents=True)
    (root / "IBUG_Flip").mkdir()
    (root / "landmarks" / "IBUG").mkdir(parents=True)
    shutil.copy(W300, root / "IBUG" / "IBUG_image_008_1_0.mat")
    m = scipy.io.loadmat(W300)
    pose = m["Pose_Para"].copy()
    pose[0, 1] += 0.2  # a rotated copy k = 1: yaw + 0.2 rad
    scipy.io.savemat(root / "IBUG" / "IBUG_image_008_1_1.mat", {"Pose_Para": pose, "pt2d": m["pt2d"]})
    flip = m["Pose_Para"].copy()
    flip[0, 1:3] *= -1
    scipy.io.savemat(root / "IBUG_Flip" / "IBUG_image_008_1_0.mat", {"Pose_Para": flip, "pt2d": m["pt2d"]})
    # landmark file in 300W-LP's key layout: pts_2d and pts_3d, 68 x 2 (image x, y)
    pts2 = m["pt2d"].T + 1.0
    pts3 = m["pt2d"].T - 2.0
    scipy.io.savemat(root / "landmarks" / "IBUG" / "IBUG_image_008_1_0_pts.mat", {"pts_2d": pts2, "pts_3d": pts3})
    return root


def test_w300lp_root(w300_root):
    src, f = table(w300_root)
    assert src.system == "300w_lp"
    assert list(f["file"]) == [
        "IBUG/IBUG_image_008_1_0.mat",
        "IBUG/IBUG_image_008_1_1.mat",
        "IBUG_Flip/IBUG_image_008_1_0.mat",
    ]
    assert list(f["subset"]) == ["IBUG"] * 3 and list(f["flipped"]) == [False, False, True]
    assert list(f["identity"]) == ["IBUG_image_008_1"] * 3 and list(f["k"]) == [0, 1, 0]
    # PROVENANCE: Pose_Para in degrees pitch -7.58, yaw -44.01, roll 3.21
    np.testing.assert_allclose(f.loc[0, ["pitch", "yaw", "roll"]].to_numpy(float), [-7.58, -44.01, 3.21], atol=0.01)
    assert f.loc[1, "yaw"] - f.loc[0, "yaw"] == pytest.approx(np.rad2deg(0.2), abs=1e-4)
    m = scipy.io.loadmat(W300)
    np.testing.assert_allclose(f.loc[0, "lm0_x"], m["pt2d"][0, 0] + 1.0)  # landmarks/ pts_2d, not pt2d
    np.testing.assert_allclose(f.loc[0, "lm3d67_y"], m["pt2d"][1, 67] - 2.0)
    assert np.isnan(f.loc[1, "lm0_x"]) and np.isnan(f.loc[2, "lm0_x"])  # no landmark file / no _Flip landmarks


def test_w300lp_zip_equals_root(w300_root, tmp_path):
    (tmp_path / "zipdir").mkdir()
    z = tmp_path / "zipdir" / "300W-LP.zip"
    with zipfile.ZipFile(z, "w") as zf:
        for p in sorted(w300_root.rglob("*.mat")):
            zf.write(p, str(Path("300W_LP") / p.relative_to(w300_root)))
    _, a = table(w300_root)
    src, b = table(z)
    assert src.system == "300w_lp"
    pd.testing.assert_frame_equal(a, b)
    assert [p.name for p in z.parent.iterdir()] == ["300W-LP.zip"]  # nothing extracted


def test_w300lp_bad_member(w300_root, tmp_path):
    (w300_root / "IBUG" / "IBUG_broken_1_0.mat").write_bytes(b"not a mat file")
    with pytest.raises(HpeError, match=r"IBUG_broken_1_0\.mat: not a readable MATLAB"):
        table(w300_root)


def test_split_name():
    from hpe_cli.datasets.w300lp import split_name

    assert split_name("IBUG_image_008_1_0") == ("IBUG_image_008_1", 0)
    assert split_name("HELEN_232194_1_17") == ("HELEN_232194_1", 17)
    assert split_name("odd") == ("odd", -1)


# ------------------------------------------------------------------------------------------------ DAD-3DHeads
def _dad_tree(root: Path, rots, scales):
    sub = root / "val"
    (sub / "annotations").mkdir(parents=True)
    items = []
    for n, (R_cv, s) in enumerate(zip(rots, scales)):
        iid = f"item{n:03d}"
        mv = np.eye(4)
        mv[:3, :3] = s * (np.diag([1.0, -1.0, -1.0]) @ R_cv)  # OpenGL camera = OpenCV camera with y, z flipped
        mv[:3, 3] = [0.01 * n, 0.02, -0.5]
        (sub / "annotations" / f"{iid}.json").write_text(
            json.dumps(
                {
                    "vertices": [[0.0, 0.0, 0.0]] * 3,
                    "model_view_matrix": mv.tolist(),
                    "projection_matrix": np.eye(4).tolist(),
                }
            )
        )
        items.append(
            {
                "item_id": iid,
                "annotation_path": f"val/annotations/{iid}.json",
                "img_path": f"val/images/{iid}.png",
                "bbox": [10 + n, 20, 30, 40],
                "attributes": {
                    "quality": "hq",
                    "gender": "female",
                    "expression": "false",
                    "age": "young",
                    "occlusions": "false",
                    "pose": "front",
                    "standard light": "true",
                },
            }
        )
    (sub / "val.json").write_text(json.dumps(items))
    return sub


def test_dad3dheads_matrix_formula(tmp_path):
    rots = Rotation.from_euler("xyz", [[10, -20, 5], [-80, 30, 170], [0, 89.9, 0]], degrees=True).as_matrix()
    _dad_tree(tmp_path, rots, [1.0, 2.5, 0.3])
    for path in (tmp_path, tmp_path / "val", tmp_path / "val" / "val.json"):
        src, f = table(path)
        assert src.system == "dad3dheads"
        R = f[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)
        mv = f[[f"mv{i}{j}" for i in range(4) for j in range(4)]].to_numpy().reshape(-1, 4, 4)
        # by hand: R = diag(1, -1, -1) @ MV[:3, :3] / s
        for k in range(3):
            s = np.cbrt(np.linalg.det(mv[k, :3, :3]))
            np.testing.assert_allclose(R[k], np.diag([1, -1, -1]) @ mv[k, :3, :3] / s, atol=1e-12)
            np.testing.assert_allclose(R[k], rots[k], atol=1e-12)
        np.testing.assert_allclose(f["mv_scale"], [1.0, 2.5, 0.3])
        assert list(f["bbox_x"]) == [10, 11, 12] and list(f["standard_light"]) == ["true"] * 3
        assert list(f["image"]) == [f"val/images/item{n:03d}.png" for n in range(3)]


def test_dad3dheads_bad_matrix(tmp_path):
    sub = _dad_tree(tmp_path, [np.eye(3)], [1.0])
    (sub / "annotations" / "item000.json").write_text(json.dumps({"model_view_matrix": [[1, 0], [0, 1]]}))
    with pytest.raises(HpeError, match=r"item000\.json: expected model_view_matrix as 4 x 4"):
        table(tmp_path)


# ------------------------------------------------------------------------------------------------ systems
def test_table_source_system(tmp_path):
    if not AFLW.exists():
        pytest.skip("real AFLW2000 sample absent")
    assert open_table(AFLW).system == "300w_lp"
    biwi = REAL / "biwi" / "db_annotations_subset"
    if biwi.exists():
        assert open_table(biwi).system == "biwi"
    p = tmp_path / "t.csv"
    pd.DataFrame({"pitch": [1.0], "yaw": [2.0], "roll": [3.0]}).to_csv(p, index=False)
    assert open_table(p).system is None
    from hpe_cli.io import TableWriter, system_metadata
    from hpe_cli.rotation.systems import get_system

    q = tmp_path / "t.parquet"
    with TableWriter(q, False, system_metadata(get_system("whenet"))) as w:
        w.write(pa.RecordBatch.from_pydict({"pitch": [1.0], "yaw": [2.0], "roll": [3.0]}))
    assert open_table(q).system == "whenet"


@pytest.fixture
def aflw430(tmp_path):
    if not (AFLW / "image00430.mat").exists():
        pytest.skip("real AFLW2000 sample absent")
    d = tmp_path / "a430"
    d.mkdir()
    for ext in (".mat", ".jpg"):
        shutil.copy(AFLW / f"image00430{ext}", d / f"image00430{ext}")
    return d


@pytest.mark.parametrize("system", ["3ddfa_v2", "scipy_zyx", "biwi"])
def test_draw_mat_reads_pose_para_as_300w_lp(aflw430, tmp_path, system):
    """image00430 looks up 34 deg: the nose points up whatever --system says (it only names the captions)."""
    from hpe_cli.io.label_source import label_source
    from hpe_cli.pipelines.draw import read_rows
    from hpe_cli.rotation.systems import get_system

    src = open_table(aflw430)
    _, A, angles, _, _ = read_rows(label_source(src, get_system(system), option_is_output=True, mode="angles"))
    nose = A[0] @ np.array([0.0, 0.0, 1.0])  # canonical: x subject's left, y up, z out of the face
    assert nose[1] > np.sin(np.deg2rad(30))  # about sin(34 deg) upwards
    w = get_system("300w_lp")
    pose = np.rad2deg(scipy.io.loadmat(aflw430 / "image00430.mat")["Pose_Para"][0, :3])
    np.testing.assert_allclose(A[0], w.to_canonical(w.from_angles(pose[None]))[0], atol=1e-12)
    s = get_system(system)
    np.testing.assert_allclose(s.to_canonical(s.from_angles(angles))[0], A[0], atol=1e-9)  # captions in --system
    # the drawn image is the same for every --system
    outs = []
    for sysname in ("300w_lp", system):
        out = tmp_path / f"d_{sysname}"
        r = hpe("draw", aflw430, "-o", out, "--system", sysname, "-q")
        assert r.exit_code == 0, r.output
        outs.append((out / "image00430.jpg").read_bytes())
    assert outs[0] == outs[1]


def test_augment_rotate0_mat_gives_target_system_angles(aflw430, tmp_path):
    from hpe_cli.rotation.systems import get_system

    out = tmp_path / "aug.csv"
    r = hpe("augment", aflw430, "-o", out, "--system", "3ddfa_v2", "--rotate", "0", "--image-size", "450", "450", "-q")
    assert r.exit_code == 0, r.output
    f = pd.read_csv(out)
    pose = np.rad2deg(scipy.io.loadmat(aflw430 / "image00430.mat")["Pose_Para"][0, :3])
    w, t = get_system("300w_lp"), get_system("3ddfa_v2")
    A = w.to_canonical(w.from_angles(pose[None]))
    got = t.to_canonical(t.from_angles(f[["pitch", "yaw", "roll"]].to_numpy()))
    np.testing.assert_allclose(got, A, atol=1e-9)
    assert not np.allclose(f[["pitch", "yaw", "roll"]].to_numpy()[0], pose, atol=1.0)  # it did convert


def test_w300lp_streams_in_chunks_same_table(w300_root):
    from hpe_cli.datasets.w300lp import open_w300lp, read_w300lp

    src = open_w300lp(w300_root, chunk=1)
    batches = list(src.iter_batches())
    assert len(batches) == 3 and src.num_rows == 3 and src.system == "300w_lp"
    f = pa.Table.from_batches(batches, schema=src.schema).to_pandas()
    full = read_w300lp(w300_root)
    pd.testing.assert_frame_equal(f[full.columns], full, check_dtype=False)


def test_dad3dheads_converts_with_the_builtin_system(tmp_path):
    from hpe_cli.rotation.systems import get_system

    try:
        get_system("dad3dheads")
    except Exception:
        pytest.skip("dad3dheads system not built in")
    rots = Rotation.from_euler("xyz", [[10, -20, 5], [-40, 30, 100]], degrees=True).as_matrix()
    _dad_tree(tmp_path, rots, [1.0, 1.0])
    out = tmp_path / "o.csv"
    r = hpe("convert", tmp_path, "-o", out, "--from", "dad3dheads", "--to", "300w_lp", "-q")
    assert r.exit_code == 0, r.output
    f = pd.read_csv(out)
    w = get_system("300w_lp")
    A = w.to_canonical(w.from_angles(f[["pitch", "yaw", "roll"]].to_numpy()))
    # by hand: R = diag(1,-1,-1) @ MV[:3,:3] and MV[:3,:3] is the canonical (OpenGL eye) rotation A
    F = np.diag([1.0, -1.0, -1.0])
    np.testing.assert_allclose(A, F @ rots, atol=1e-9)
    assert list(f["item_id"]) == ["item000", "item001"]


def test_evaluate_mat_gt_is_300w_lp_whatever_gt_system(aflw430, tmp_path):
    """A prediction equal to the .mat label scores 0 whatever --gt-system names (it names the reporting system)."""
    import json

    pose = np.rad2deg(scipy.io.loadmat(aflw430 / "image00430.mat")["Pose_Para"][0, :3].astype(np.float64))
    pred = tmp_path / "pred.csv"
    pd.DataFrame({"file": ["image00430.mat"], "pitch": [pose[0]], "yaw": [pose[1]], "roll": [pose[2]]}).to_csv(
        pred, index=False
    )
    for gsys in ("300w_lp", "3ddfa_v2"):
        rep = tmp_path / f"{gsys}.json"
        r = hpe(
            "evaluate",
            pred,
            aflw430,
            "--pred-system",
            "300w_lp",
            "--gt-system",
            gsys,
            "--key",
            "file",
            "--json",
            rep,
            "-q",
        )
        assert r.exit_code == 0, r.output
        assert json.loads(rep.read_text())["metrics"]["geodesic"]["max"] < 1e-6
