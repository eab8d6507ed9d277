"""Build the synthetic AGORA ground-truth fixture in ``tests/data/agora/``.

No real AGORA ``*_withjv.pkl`` is public, so this writes a small one in the
same layout (one row per image, per-person lists; see
``hpe_cli/datasets/agora.py`` and AGORA's ``docs/gt_dataframe.md``), with the
camera columns DirectMHP adds (``cam_j3d, camR, camT, camK``). ``gt_verts``
is left out (10475 x 3 per person, unused).

Every face is WHENet's reference head turned by a rotation chosen so that the
head, *as the camera sees it*, has known labels: the test oracle is the list
of target angles below, not anything computed by hpe. The 13 landmarks that
DirectMHP pairs with the reference head are the reference head's own points;
the other 38 of the 51 face joints come from the iBUG-68 mean shape
(``hpe_cli/data/reference_3d_68_points_trans.npy``) mapped onto the head.
Some people are built to be rejected, one reason each.

Usage::

    python scripts/make_agora_fixture.py [OUT_DIR]

It writes ``validation_0_withjv.pkl`` (pandas pickle, protocol 4) and
``expected.json`` (per person: image, person index, target whenet angles,
expected status) and is deterministic.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
REF = json.loads((ROOT / "hpe_cli" / "data" / "whenet_reference_head.json").read_text())
HEAD = np.asarray(REF["points"], dtype=np.float64)  # (58, 3), head units ~ cm
F51 = np.asarray(REF["agora_face51_pairs"]["face51"])
H13 = np.asarray(REF["agora_face51_pairs"]["head"])
IBUG = np.load(ROOT / "hpe_cli" / "data" / "reference_3d_68_points_trans.npy").astype(np.float64)
E = np.diag([1.0, -1.0, -1.0])
W, H = 3840, 2160  # the resolution the dataframe is "built" for (camK, gt_joints_2d)
N_JOINTS = 127

# image name, focal length (mm, AGORA's rule for that scene), camera pitch / yaw (deg)
IMAGES = [
    ("ag_validationset_renderpeople_bfh_flowers_5_15_00000.png", 28.0, 0.0, 0.0),
    ("ag_validationset_renderpeople_bfh_archviz_5_10_cam02_00001.png", 18.0, 30.0, -45.0),
    ("ag_validationset_renderpeople_bfh_hdri_50mm_5_10_00002.png", 50.0, 0.0, 0.0),
]

# per person: image, target 300W-LP (pitch, yaw, roll) deg as the camera sees the head, head centre in the
# camera frame (m, OpenCV), body yaw (deg), occlusion, isValid, what to break, expected status
PEOPLE = [
    (0, (5.0, 10.0, -3.0), (-0.8, -0.1, 5.0), 10.0, 10.0, True, None, "ok"),
    (0, (-10.0, 70.0, 5.0), (0.6, 0.0, 6.0), 80.0, 0.0, True, None, "ok"),
    (0, (15.0, 150.0, 10.0), (1.5, 0.2, 7.0), 200.0, 30.0, True, None, "ok"),
    (0, (0.0, -20.0, 0.0), (-1.5, 0.0, 6.0), -30.0, 95.0, False, None, "occluded"),
    (0, (0.0, 30.0, 0.0), (0.0, 0.3, 8.0), 40.0, 40.0, False, None, "invalid"),
    (1, (-30.0, -120.0, 20.0), (-0.5, 0.0, 4.0), -100.0, 5.0, True, None, "ok"),
    (1, (0.0, 0.0, 0.0), (0.5, 0.1, 4.5), 0.0, 0.0, True, "few", "too few confident points"),
    (1, (10.0, 20.0, 0.0), (1.0, 0.2, 5.0), 20.0, 0.0, True, "noise", "bad fit"),
    (1, (0.0, 0.0, 0.0), (0.0, 0.0, -2.0), 0.0, 0.0, True, None, "behind camera"),
    # 300W-LP (120, 20, 10): neither Euler triple has |pitch| < 90 and |roll| < 90
    (1, (120.0, 20.0, 10.0), (-1.0, 0.3, 5.0), 0.0, 0.0, True, None, "ok; dropped by legacy rule"),
    (2, (0.0, 10.0, 0.0), (0.0, 0.0, 0.6), 0.0, 0.0, True, None, "box rejected"),
    (2, (0.0, -10.0, 0.0), (-1.41, 0.0, 4.0), 0.0, 0.0, True, None, "box rejected"),
    (2, (0.0, 0.0, 0.0), (-1.9, 0.0, 4.0), 0.0, 0.0, True, None, "outside image"),
    (2, (0.0, 0.0, 0.0), (0.3, 0.05, 3.0), 0.0, 0.0, True, None, "ok"),
]


def rot_y(deg):
    return Rotation.from_rotvec([0.0, np.deg2rad(deg), 0.0]).as_matrix()


def rot_x(deg):
    return Rotation.from_rotvec([np.deg2rad(deg), 0.0, 0.0]).as_matrix()


def canonical(p, y, r):
    """The 300W-LP matrix Rx(p).T @ Ry(y).T @ Rz(r).T (SPEC §2), via SciPy's intrinsic XYZ."""
    return Rotation.from_euler("XYZ", [-p, -y, -r], degrees=True).as_matrix()


def face_points_head_units():
    """51 face joints in reference-head units: the 13 paired points exact, the rest from the iBUG-68 mean."""
    src = IBUG[F51 + 17]
    dst = HEAD[H13]
    # similarity iBUG -> head on the 13 pairs (Umeyama)
    ms, md = src.mean(0), dst.mean(0)
    U, S, Vt = np.linalg.svd((dst - md).T @ (src - ms))
    d = np.sign(np.linalg.det(U @ Vt))
    R = U @ np.diag([1, 1, d]) @ Vt
    s = (S * [1, 1, d]).sum() / ((src - ms) ** 2).sum()
    pts = s * (IBUG[17:] - ms) @ R.T + md
    pts[F51] = HEAD[H13]
    return pts


def main(out_dir: Path) -> None:
    rng = np.random.default_rng(20240611)
    face51 = face_points_head_units()
    rows = {
        name: {
            k: []
            for k in (
                "X",
                "Y",
                "Z",
                "Yaw",
                "gender",
                "kid",
                "age",
                "occlusion",
                "isValid",
                "gt_path_smplx",
                "gt_joints_2d",
                "gt_joints_3d",
                "cam_j3d",
                "camR",
                "camT",
                "camK",
            )
        }
        for name, *_ in IMAGES
    }
    expected = []
    for k, (img, target, centre, body_yaw, occ, valid, spoil, status) in enumerate(PEOPLE):
        name, focal, cam_pitch, cam_yaw = IMAGES[img]
        r = rows[name]
        # AGORA's camR: camera pitch, camera yaw, then the body's own yaw (all about OpenCV axes)
        camR = rot_x(cam_pitch) @ rot_y(-cam_yaw) @ rot_y(body_yaw - 90.0)
        A = canonical(*target)
        R_head = camR.T @ E @ A  # so that E @ camR @ R_head = A
        scale = 0.0095 + 0.001 * rng.random()  # metres per head unit
        head_in_body = np.array([0.02, -0.55, 0.03]) + 0.02 * rng.standard_normal(3)
        camT = np.asarray(centre) - camR @ head_in_body
        joints = np.empty((N_JOINTS, 3))
        # body joints: a rough column below the head (y down in the body frame)
        joints[:76] = head_in_body + np.column_stack(
            [0.15 * rng.standard_normal(76), np.linspace(0.1, 1.4, 76), 0.05 * rng.standard_normal(76)]
        )
        face = scale * face51 @ R_head.T + head_in_body
        if spoil == "few":
            face[F51[:7]] = np.nan
        elif spoil == "noise":
            face += 0.04 * rng.standard_normal(face.shape)
        joints[76:] = face
        j3d = joints @ camR.T + camT
        K = np.array([[focal / 36.0 * W, 0.0, W / 2.0], [0.0, focal / 20.25 * H, H / 2.0], [0.0, 0.0, 1.0]])
        with np.errstate(invalid="ignore", divide="ignore"):
            j2d = (j3d @ K.T)[:, :2] / j3d[:, 2:3]
        r["X"].append(float(centre[0]))
        r["Y"].append(float(centre[1]))
        r["Z"].append(float(centre[2]))
        r["Yaw"].append(float(body_yaw))
        r["gender"].append(["female", "male"][k % 2])
        r["kid"].append(False)
        r["age"].append("31-50")
        r["occlusion"].append(float(occ))
        r["isValid"].append(bool(valid))
        r["gt_path_smplx"].append(f"smplx_gt/fixture/person_{k:02d}.obj")
        r["gt_joints_2d"].append(j2d)
        r["gt_joints_3d"].append(j3d)
        r["cam_j3d"].append(joints)
        r["camR"].append(camR)
        r["camT"].append(camT.reshape(3, 1))
        r["camK"].append(K)
        expected.append(
            {"image": name, "row": img, "person": len(r["isValid"]) - 1, "target": list(target), "status": status}
        )
    records = []
    for name, focal, cam_pitch, cam_yaw in IMAGES:
        rec = {"imgPath": name, "camX": 0.0, "camY": 0.0, "camZ": 170.0, "camYaw": cam_yaw}
        rec.update(rows[name])
        records.append(rec)
    cols = [
        "imgPath",
        "X",
        "Y",
        "Z",
        "Yaw",
        "camX",
        "camY",
        "camZ",
        "camYaw",
        "gender",
        "kid",
        "age",
        "occlusion",
        "isValid",
        "gt_path_smplx",
        "gt_joints_2d",
        "gt_joints_3d",
        "cam_j3d",
        "camR",
        "camT",
        "camK",
    ]
    df = pd.DataFrame(records)[cols]
    out_dir.mkdir(parents=True, exist_ok=True)
    df.to_pickle(out_dir / "validation_0_withjv.pkl", protocol=4)
    (out_dir / "expected.json").write_text(
        json.dumps(
            {
                "image_size": [W, H],
                "note": "target: (pitch, yaw, roll) degrees with A = Rx(p).T @ Ry(y).T @ Rz(r).T the head as the camera "
                "sees it; when |pitch| < 90 and |roll| < 90 it is also the whenet (DirectMHP) label",
                "people": expected,
            },
            indent=1,
        )
        + "\n"
    )
    print(f"wrote {out_dir / 'validation_0_withjv.pkl'} ({len(df)} images, {len(expected)} people)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "tests" / "data" / "agora")
