"""AGORA reader and relabelling on the synthetic fixture (``scripts/make_agora_fixture.py``).

The oracle is the fixture's list of *chosen* head poses (``expected.json``),
SPEC §2's two-solution formulas, AGORA's own conventions (``camR @ cam_j3d +
camT = gt_joints_3d``; 1280x720 pixels are 4K pixels times 720/2160), and
physics (where the nose goes in the image).
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hpe_cli.datasets.agora import FACE_COUNT, FACE_FIRST, agora_intrinsics, read_agora
from hpe_cli.errors import HpeError
from hpe_cli.pipelines.relabel.agora import Config, relabel_people

DATA = Path(__file__).resolve().parents[1] / "data" / "agora"
PKL = DATA / "validation_0_withjv.pkl"
EXPECTED = json.loads((DATA / "expected.json").read_text())["people"]


def _status(legacy=False):
    out = {}
    for e in EXPECTED:
        s = e["status"]
        if s.startswith("ok;"):
            s = s.split("; ")[1] if legacy else "ok"
        out[(e["row"], e["person"])] = s
    return out


def _solution1(p, y, r):
    """SPEC §2: the 300W-LP triple with |yaw| <= 90 of the rotation whose other triple is (p, y, r)."""
    if abs(y) <= 90:
        return (p, y, r)
    y1 = 180 - y if y >= 0 else -180 - y
    p1 = p - 180 if p >= 0 else p + 180
    r1 = r - 180 if r >= 0 else r + 180
    return (p1, y1, r1)


@pytest.fixture(scope="module")
def df():
    return pd.read_pickle(PKL)


@pytest.fixture(scope="module")
def people():
    return read_agora(PKL)


def _by_key(table):
    return {(int(r), int(p)): k for k, (r, p) in enumerate(zip(table["row"], table["person"]))}


# ------------------------------------------------------------------- fixture
def test_fixture_has_agoras_layout(df):
    for col in (
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
        "occlusion",
        "isValid",
        "gt_joints_2d",
        "gt_joints_3d",
        "cam_j3d",
        "camR",
        "camT",
        "camK",
    ):
        assert col in df.columns
    for _, row in df.iterrows():
        n = len(row["isValid"])
        for col in ("occlusion", "gt_joints_2d", "gt_joints_3d", "cam_j3d", "camR", "camT", "camK", "X", "Yaw"):
            assert len(row[col]) == n
        for j2, j3, cj, R, t, K in zip(
            row["gt_joints_2d"], row["gt_joints_3d"], row["cam_j3d"], row["camR"], row["camT"], row["camK"]
        ):
            assert j2.shape == (127, 2) and j3.shape == (127, 3) and cj.shape == (127, 3)
            assert R.shape == (3, 3) and t.shape == (3, 1) and K.shape == (3, 3)
            # AGORA's own relation between DirectMHP's columns and its camera-frame joints
            np.testing.assert_allclose(cj @ R.T + t[:, 0], j3, atol=1e-12, equal_nan=True)
            with np.errstate(invalid="ignore"):
                uv = (j3 @ K.T)[:, :2] / j3[:, 2:]
            np.testing.assert_allclose(uv, j2, atol=1e-9, equal_nan=True)


def test_read_agora_flattens_people(people, df):
    assert len(people) == 14 and people.images == 3 and people.frame == "body"
    assert list(people.row) == [0] * 5 + [1] * 5 + [2] * 4
    assert list(people.person) == list(range(5)) * 2 + list(range(4))
    k = 7
    r, p = people.row[k], people.person[k]
    np.testing.assert_array_equal(people.face3d[k], df["cam_j3d"][r][p][FACE_FIRST : FACE_FIRST + FACE_COUNT])
    np.testing.assert_array_equal(people.cam_t[k], df["camT"][r][p][:, 0])
    assert people.image[k] == df["imgPath"][r]
    assert people.occlusion[3] == 95.0 and not people.valid[3]


# -------------------------------------------------------------------- labels
@pytest.mark.parametrize("system", ["300w_lp", "whenet"])
def test_labels_recover_the_chosen_poses(people, system):
    res = relabel_people(people, Config(system=system))
    t = res["table"]
    at = _by_key(t)
    status = _status()
    assert sorted(at) == sorted(k for k, s in status.items() if s == "ok")
    for e in EXPECTED:
        k = at.get((e["row"], e["person"]))
        if k is None:
            continue
        p, y, r = e["target"]
        want = _solution1(p, y, r) if system == "300w_lp" else (p, y, r)
        got = (t["pitch"][k], t["yaw"][k], t["roll"][k])
        np.testing.assert_allclose(got, want, atol=1e-6, err_msg=str(e))
        assert t["n_pairs"][k] == 13 and t["fit_rmse"][k] < 1e-9
        assert 0.0095 <= t["scale"][k] <= 0.0105  # metres per reference-head unit, as built


def test_reject_reasons_match_the_fixture(people):
    for legacy in (False, True):
        res = relabel_people(people, Config(system="whenet", legacy=legacy))
        rj = res["rejects"]
        got = {(int(r), int(p)): s for r, p, s in zip(rj["row"], rj["person"], rj["reason"])}
        want = {k: s for k, s in _status(legacy).items() if s != "ok"}
        assert got == want
        # every person is either labelled or rejected, exactly once
        assert len(res["table"]["row"]) + len(rj["row"]) == len(people)


def test_legacy_chain_equals_the_corrected_labels(people):
    res = relabel_people(people, Config(system="whenet", legacy=True))
    t = res["table"]
    for a, b in (("pitch", "legacy_pitch"), ("yaw", "legacy_yaw"), ("roll", "legacy_roll")):
        np.testing.assert_allclose(t[a], t[b], atol=1e-9)


def test_nose_turns_with_yaw_and_box_holds_the_face(people):
    t = relabel_people(people, Config(system="300w_lp"))["table"]
    xs = np.stack([t[f"lm{i}_x"] for i in range(FACE_COUNT)], 1)
    ys = np.stack([t[f"lm{i}_y"] for i in range(FACE_COUNT)], 1)
    # iBUG 30 (nose tip) = face joint 13; iBUG 36 / 45 (outer eye corners) = 19 / 28
    eyes_mid = (xs[:, 19] + xs[:, 28]) / 2
    for k in range(len(t["yaw"])):
        if 5 < abs(t["yaw"][k]) < 90 and abs(t["pitch"][k]) < 45:
            assert np.sign(xs[k, 13] - eyes_mid[k]) == -np.sign(t["yaw"][k])  # positive yaw: nose to the left
        x, y, w, h = t["bbox_x"][k], t["bbox_y"][k], t["bbox_w"][k], t["bbox_h"][k]
        assert (xs[k] >= x).all() and (xs[k] <= x + w).all() and (ys[k] >= y).all() and (ys[k] <= y + h).all()
        assert max(w / h, h / w) < 1.5 and w < 0.7 * 3840 and h < 0.7 * 2160  # DirectMHP's rule


def test_landmarks_are_agoras_2d_joints(people, df):
    t = relabel_people(people, Config(system="300w_lp"))["table"]
    for k, (r, p) in enumerate(zip(t["row"], t["person"])):
        j2 = df["gt_joints_2d"][r][p][FACE_FIRST : FACE_FIRST + FACE_COUNT]
        np.testing.assert_allclose(t["lm5_x"][k], j2[5, 0], atol=1e-6)
        np.testing.assert_allclose(t["lm50_y"][k], j2[50, 1], atol=1e-6)


def test_720p_is_4k_times_one_third(people, df):
    big = relabel_people(people, Config(system="300w_lp"))["table"]
    small = relabel_people(people, Config(system="300w_lp", image_size=(1280, 720)))["table"]
    a, b = _by_key(big), _by_key(small)
    assert set(b) <= set(a)
    for key, kb in b.items():
        ka = a[key]
        for c in ("pitch", "yaw", "roll"):
            assert small[c][kb] == pytest.approx(big[c][ka], abs=1e-9)
        for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h", "lm0_x", "lm30_y"):
            assert small[c][kb] == pytest.approx(big[c][ka] / 3.0, abs=1e-6)
        r, p = key
        # AGORA's docs: 1280x720 joints = 4K joints * 720 / 2160
        j2 = df["gt_joints_2d"][r][p][FACE_FIRST : FACE_FIRST + FACE_COUNT] * (720 / 2160)
        assert small["lm7_x"][kb] == pytest.approx(j2[7, 0], abs=1e-6)


def test_camera_frame_fallback_gives_the_same_labels(df, tmp_path, people):
    cam_only = df.drop(columns=["cam_j3d", "camR", "camT", "camK"])
    f = tmp_path / "agora_release_withjv.pkl"
    cam_only.to_pickle(f)
    p2 = read_agora(f)
    assert p2.frame == "camera"
    # AGORA's intrinsics rule rebuilds the fixture's camK
    K_rule = agora_intrinsics(p2.image, 3840, 2160)
    np.testing.assert_allclose(K_rule, people.K, rtol=1e-12)
    a = relabel_people(people, Config(system="300w_lp"))
    b = relabel_people(p2, Config(system="300w_lp"))
    assert list(a["rejects"]["reason"]) == list(b["rejects"]["reason"])
    for c in ("pitch", "yaw", "roll", "bbox_x", "bbox_w", "lm13_x", "r01", "fit_rmse"):
        np.testing.assert_allclose(a["table"][c], b["table"][c], atol=1e-8)


def test_agora_intrinsics_by_scene():
    K = agora_intrinsics(["x_hdri_50mm_1.png", "ag_trainset_archviz_cam01_2.png", "ag2_x.png", "plain.png"], 3840, 2160)
    np.testing.assert_allclose(K[:, 0, 0], np.array([50, 18, 28, 28]) / 36 * 3840)
    np.testing.assert_allclose(K[:, 1, 1], np.array([50, 18, 28, 28]) / 20.25 * 2160)
    np.testing.assert_allclose(K[:, :2, 2], [[1920, 1080]] * 4)


# -------------------------------------------------------------------- errors
def test_wrong_aspect_image_size(people):
    with pytest.raises(HpeError, match="validation_0_withjv.pkl: row 0: camK's principal point"):
        relabel_people(people, Config(image_size=(1000, 1000)))


@pytest.mark.parametrize(
    "drop, name", [(["occlusion"], "occlusion"), (["imgPath"], "imgPath"), (["camK", "gt_joints_3d"], "camK")]
)
def test_missing_column(df, tmp_path, drop, name):
    f = tmp_path / "bad_withjv.pkl"
    df.drop(columns=drop).to_pickle(f)
    with pytest.raises(HpeError) as err:
        read_agora(f)
    msg = str(err.value)
    assert msg.startswith(f"{f}: missing column {name!r}") and "\n" not in msg


def test_not_a_dataframe_and_truncated(tmp_path):
    f = tmp_path / "list.pkl"
    f.write_bytes(pickle.dumps([1, 2, 3]))
    with pytest.raises(HpeError, match="list.pkl: expected a pandas DataFrame"):
        read_agora(f)
    cut = tmp_path / "cut_withjv.pkl"
    cut.write_bytes(PKL.read_bytes()[:5000])
    with pytest.raises(HpeError, match="cut_withjv.pkl: cannot load the pickle"):
        read_agora(cut)


def test_ragged_person_lists(df, tmp_path):
    bad = df.copy()
    bad.at[1, "occlusion"] = bad["occlusion"][1][:-1]
    f = tmp_path / "ragged.pkl"
    bad.to_pickle(f)
    with pytest.raises(HpeError, match="ragged.pkl: row 1: column 'occlusion' has 4 entries, expected 5"):
        read_agora(f)


def test_wrong_joint_shape(df, tmp_path):
    bad = df.copy()
    lst = list(bad["cam_j3d"][2])
    lst[1] = lst[1][:100]
    bad.at[2, "cam_j3d"] = lst
    f = tmp_path / "short.pkl"
    bad.to_pickle(f)
    with pytest.raises(
        HpeError, match=r"short.pkl: row 2, person 1: cam_j3d: expected a \(J, 3\) array .*got shape \(100, 3\)"
    ):
        read_agora(f)


def test_empty_dataframe_and_rows_without_people(df, tmp_path):
    f = tmp_path / "empty.pkl"
    df.iloc[:0].to_pickle(f)
    p = read_agora(f)
    assert len(p) == 0 and p.images == 0
    res = relabel_people(p, Config())
    assert len(res["table"]["row"]) == 0 and len(res["rejects"]["row"]) == 0
    holey = df.copy()
    for col in ("isValid", "occlusion", "gt_joints_2d", "gt_joints_3d", "cam_j3d", "camR", "camT", "camK"):
        holey.at[1, col] = ""  # AGORA's placeholder where nothing was stored
    f = tmp_path / "holey.pkl"
    holey.to_pickle(f)
    p = read_agora(f)
    assert len(p) == 9 and set(p.row) == {0, 2}
