#!/usr/bin/env python3
"""Build ``sample_data/``: a synthetic CMU Panoptic sequence and a few real frames.

Deterministic: the same command always writes the same bytes.

1. ``sample_data/panoptic_synth/``: a small synthetic sequence with known
   head rotations, in Panoptic's layout. Its HD cameras imitate the
   160906_pizza1 calibration (focal lengths, principal points, distortion,
   a dome of radius ~2.8 m looking at the middle of the room, y down, cm).
   Face landmarks are an exact similarity of a face70 template whose 14
   WHENet landmarks are WHENet's reference head points, so a correct relabel
   recovers each label to ~1e-12 degrees. It has frame gaps, a person-id
   gap, face files of version 0.5 and 0.7 (with ``univTime``), a face with
   no confident points, one with exactly 7 confident pairs (kept) and one
   with 6 (rejected), and two more HD cameras that see no face (one faces
   the wall, one looks off to the side). ``ground_truth.csv`` lists every face's rotation,
   scale and translation, and what should happen to it.
2. ``sample_data/panoptic_160906_pizza1/``: the real calibration (HD cameras
   only) and four real face frames of CMU Panoptic's 160906_pizza1, copied
   from ``../shared/realdata`` when it exists (see ``sample_data/ATTRIBUTION.md``).

3. With ``--tar`` the face files are packed into ``hdFace3d.tar`` (as
   downloaded) and the folder removed; with ``--videos`` each HD camera gets a
   short ``hdVideos/hd_00_XX.mp4`` (``cv2.VideoWriter``, mp4v) whose frame k
   shows k as a row of 16 black/white blocks (:func:`encode_frame_number`,
   read back by :func:`decode_frame_number`, robust to compression), from
   frame 0 to the last face frame.

Usage::

    python scripts/make_sample_data.py            # writes sample_data/
    python scripts/make_sample_data.py --out DIR --frames 2000 --people 5 --cameras 31 --plain
    python scripts/make_sample_data.py --out DIR --frames 20000 --plain --tar --videos --video-size 192x108
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "realdata" / "panoptic_160906_pizza1"
REAL_FRAMES = (1147, 3476, 5777, 6577)
SYNTH_NAME = "panoptic_synth"

#: OpenPose face70: iBUG-68 plus the right (68) and left (69) pupils
RIGHT_EYE, LEFT_EYE = list(range(36, 42)), list(range(42, 48))


# ------------------------------------------------------------------ template
def _umeyama(src, dst):
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    U, D, Vt = np.linalg.svd(b.T @ a)
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ S @ Vt
    s = np.trace(np.diag(D) @ S) / (a * a).sum()
    return s, R, mu_d - s * R @ mu_s


def face70_template() -> np.ndarray:
    """A face70 template (70, 3) in WHENet's reference-head frame and units.

    The iBUG-68 mean shape shipped in ``hpe_cli/data`` (frame: x subject's
    left, y down, z into the head) is fitted onto the reference head through
    WHENet's 14 pairs; then those 14 landmarks are set to the reference
    points exactly, and the pupils are the eye-corner means.
    """
    data = ROOT / "hpe_cli" / "data"
    ref = json.loads((data / "whenet_reference_head.json").read_text())
    head = np.asarray(ref["points"], dtype=np.float64)
    f70 = np.asarray(ref["panoptic_face70_pairs"]["face70"])
    h = np.asarray(ref["panoptic_face70_pairs"]["head"])
    ibug = np.load(data / "reference_3d_68_points_trans.npy").astype(np.float64)
    s, R, t = _umeyama(ibug[f70], head[h])
    tpl = np.zeros((70, 3))
    tpl[:68] = s * ibug @ R.T + t
    tpl[f70] = head[h]
    tpl[68] = tpl[RIGHT_EYE].mean(0)
    tpl[69] = tpl[LEFT_EYE].mean(0)
    return tpl


# ------------------------------------------------------------------- cameras
def _look_at(C, target, roll_deg):
    z = target - C
    z /= np.linalg.norm(z)
    down = np.array([0.0, 1.0, 0.0])  # Panoptic's world y points to the floor
    x = np.cross(down, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    c, s = np.cos(np.deg2rad(roll_deg)), np.sin(np.deg2rad(roll_deg))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ R
    return R, -R @ C


def dome_cameras(n: int, rng) -> list:
    """``n`` HD cameras on a dome around the room centre, Panoptic-style dicts."""
    cams = []
    for i in range(n):
        az = 2 * np.pi * i / n + rng.uniform(-0.05, 0.05)
        radius = rng.uniform(265, 285)
        height = rng.uniform(-210, -110)
        C = np.array([radius * np.cos(az), height, radius * np.sin(az)])
        target = np.array([0.0, -140.0, 0.0]) + rng.uniform(-15, 15, 3)
        R, t = _look_at(C, target, rng.uniform(-2, 2))
        f = rng.uniform(1400, 1650)
        K = [
            [round(f, 2), 0, round(rng.uniform(938, 950), 3)],
            [0, round(f * rng.uniform(0.996, 0.998), 2), round(rng.uniform(555, 566), 3)],
            [0, 0, 1],
        ]
        dist = [
            rng.uniform(-0.29, -0.22),
            rng.uniform(0.18, 0.21),
            rng.uniform(-6e-4, 2e-4),
            rng.uniform(-2e-4, 1e-3),
            rng.uniform(-0.06, 0.03),
        ]
        cams.append(
            {
                "name": f"00_{i:02d}",
                "type": "hd",
                "resolution": [1920, 1080],
                "panel": 0,
                "node": i,
                "K": K,
                "distCoef": [round(float(d), 6) for d in dist],
                "R": R.tolist(),
                "t": [[float(v)] for v in t],
            }
        )
    return cams


def odd_cameras(first: int, rng) -> list:
    """Two more HD cameras that see no face: one faces the wall (every head is behind
    it), one looks 70 degrees to the side of the room centre (heads in front, off the image)."""
    base = dome_cameras(first + 2, rng)[first:]
    for cam, turn in zip(base, (np.pi, np.deg2rad(70))):
        R = np.asarray(cam["R"])
        C = -R.T @ np.asarray(cam["t"])[:, 0]
        Rn = R.T @ _ry_cam(turn)  # rotate the viewing direction about the camera's own y axis
        cam["R"] = Rn.T.tolist()
        cam["t"] = [[float(v)] for v in -Rn.T @ C]
    return base


def _ry_cam(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def other_cameras(rng) -> list:
    """One VGA and one Kinect camera, so that the default ``hd`` selection matters."""
    out = []
    for name, typ, res, f, panel in (
        ("01_01", "vga", [640, 480], 745.0, 1),
        ("50_01", "kinect-color", [1920, 1080], 1060.0, 50),
    ):
        R, t = _look_at(np.array([0.0, -250.0, 270.0]), np.array([0.0, -140.0, 0.0]), 0.0)
        out.append(
            {
                "name": name,
                "type": typ,
                "resolution": res,
                "panel": panel,
                "node": 1,
                "K": [[f, 0, res[0] / 2], [0, f, res[1] / 2], [0, 0, 1]],
                "distCoef": [-0.3, 0.1, 0, 0, 0],
                "R": R.tolist(),
                "t": [[float(v)] for v in t],
            }
        )
    return out


# --------------------------------------------------------------------- heads
def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


#: head frame (x: subject's left, y: up, z: out of the face) -> world for an
#: upright head facing +z in Panoptic's world (y down)
R_UPRIGHT = np.diag([-1.0, -1.0, 1.0])


def head_pose(k: int, frame_index: int, params) -> tuple:
    """Rotation, translation and scale of person ``k`` at a frame (smooth, full-range yaw)."""
    yaw0, spin, pitch_amp, roll_amp, phase, centre, scale = params[k]
    u = frame_index * 0.21 + phase
    heading = yaw0 + spin * frame_index  # turns all the way round over the sequence
    R = _ry(heading) @ R_UPRIGHT @ _rx(pitch_amp * np.sin(u)) @ _rz(roll_amp * np.sin(1.7 * u))
    t = centre + np.array([3.0 * np.sin(u), 1.5 * np.sin(2 * u), 3.0 * np.cos(u)])
    return R, t, scale


def person_params(n: int, rng) -> list:
    out = []
    for k in range(n):
        ang = 2 * np.pi * k / n + rng.uniform(-0.3, 0.3)
        r = rng.uniform(30, 70)
        centre = np.array([r * np.cos(ang), rng.uniform(-170, -145), r * np.sin(ang)])
        out.append(
            (
                rng.uniform(-np.pi, np.pi),
                rng.uniform(0.15, 0.35) * rng.choice([-1, 1]),
                np.deg2rad(rng.uniform(15, 45)),
                np.deg2rad(rng.uniform(5, 30)),
                rng.uniform(0, 6),
                centre,
                rng.uniform(0.88, 1.0),
            )
        )
    return out


# ------------------------------------------------------------------- writing
def _visibility(nodes, rng) -> list:
    """Per landmark, the cameras that saw it (real files list 5-10 of them)."""
    k = min(len(nodes), int(rng.integers(5, 11)))
    seen = sorted(rng.choice(nodes, size=k, replace=False).tolist())
    return [seen for _ in range(70)]


def _num(v: float) -> float:
    return float(v)  # json writes repr(), which round-trips float64 exactly


def make_synthetic(
    out_dir,
    n_frames: int = 24,
    n_people: int = 3,
    n_cameras: int = 5,
    seed: int = 20240611,
    first_frame: int = 100,
    special: bool = True,
) -> dict:
    """Write a synthetic Panoptic sequence into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        The sequence folder (created); its name is the sequence name.
    n_frames : int
        Frame numbers ``first_frame .. first_frame + n_frames - 1``; with
        ``special`` a few of them are left out (gaps).
    n_people, n_cameras : int
    seed : int
    special : bool
        Add the edge cases (gaps, id gap, versions 0.5/0.7, low-confidence
        faces, extra camera types). ``False`` writes a plain sequence (benchmarks).

    Returns
    -------
    dict
        ``heads``: list of ground-truth rows (also written to ``ground_truth.csv``).
    """
    out = Path(out_dir)
    seq = out.name
    (out / "hdFace3d").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    tpl = face70_template()
    ref = json.loads((ROOT / "hpe_cli" / "data" / "whenet_reference_head.json").read_text())
    pairs = np.asarray(ref["panoptic_face70_pairs"]["face70"])
    cams = dome_cameras(n_cameras, rng)
    extra = odd_cameras(n_cameras, rng) + other_cameras(rng) if special else []
    calib = {"calibDataSource": f"{seq}_synthetic", "cameras": cams + extra}
    (out / f"calibration_{seq}.json").write_text(json.dumps(calib, indent=1) + "\n")

    ids = [0, 1, 3, 4, 6, 7, 8, 9][:n_people] if special else list(range(n_people))
    params = person_params(n_people, rng)
    frames = list(range(first_frame, first_frame + n_frames))
    if special:
        gaps = {first_frame + 4, first_frame + 5, first_frame + 11}
        frames = [f for f in frames if f not in gaps]
    nodes = [c["node"] for c in cams]
    heads = []
    for fi, frame in enumerate(frames):
        people = []
        for k, pid in enumerate(ids):
            R, t, s = head_pose(k, frame - first_frame, params)
            lm = s * tpl @ R.T + t
            score = rng.uniform(0.4, 0.85, 70)
            expect, note = "labelled", ""
            if special and fi == 2 and k == n_people - 1:
                score[:] = rng.uniform(0.0, 0.05, 70)
                expect, note = "too few confident points", "low-confidence face (no pair above 0.1)"
            elif special and fi == 5 and k == 0:
                score[pairs[:7]] = 0.1  # exactly 0.1 is not confident (WHENet uses > 0.1)
                note = "exactly 7 confident pairs (WHENet's minimum)"
            elif special and fi == 6 and k == 0:
                score[pairs[:8]] = 0.05
                expect, note = "too few confident points", "6 confident pairs (one short)"
            person = {
                "id": pid,
                "face70": {
                    "landmarks": [_num(v) for v in lm.reshape(-1)],
                    "averageScore": [round(float(v), 6) for v in score],
                    "averageReproError": [round(float(v), 6) for v in rng.uniform(1.0, 3.5, 70)],
                    "visibility": _visibility(nodes, rng),
                },
            }
            if special and fi % 4 == 1:
                person["face70"]["someFutureField"] = 1  # readers must ignore unknown fields
            people.append(person)
            heads.append(
                {
                    "frame": frame,
                    "person_id": pid,
                    "scale": s,
                    "t_x": t[0],
                    "t_y": t[1],
                    "t_z": t[2],
                    **{f"head_r{i}{j}": R[i, j] for i in range(3) for j in range(3)},
                    "n_confident_pairs": int((score[pairs] > 0.1).sum()),
                    "expected": expect,
                    "note": note,
                }
            )
        doc = {"version": 0.5, "people": people}
        if not special or fi % 2:
            doc = {
                "version": 0.7,
                "univTime": round(1000.0 + frame / 29.97, 3),
                "fpsType": "hd_29_97",
                "people": people,
            }
        (out / "hdFace3d" / f"faceRecon3D_hd{frame:08d}.json").write_text(json.dumps(doc))
    if special:
        with open(out / "ground_truth.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(heads[0]), lineterminator="\n")
            w.writeheader()
            for row in heads:
                w.writerow({k: (repr(float(v)) if isinstance(v, (float, np.floating)) else v) for k, v in row.items()})
    return {"heads": heads, "frames": frames, "cameras": cams}


# ------------------------------------------------------ archives and videos
BITS = 16


def encode_frame_number(k: int, width: int = 192, height: int = 108) -> np.ndarray:
    """A BGR image showing ``k`` as 16 black/white blocks (most significant bit left),
    on a mid-grey background, with a white guard block before and a black one after."""
    img = np.full((height, width, 3), 128, np.uint8)
    bw = width // (BITS + 2)
    y0, y1 = height // 4, 3 * height // 4
    img[y0:y1, 0:bw] = 255
    for b in range(BITS):
        on = (int(k) >> (BITS - 1 - b)) & 1
        img[y0:y1, (b + 1) * bw : (b + 2) * bw] = 255 if on else 0
    img[y0:y1, (BITS + 1) * bw : (BITS + 2) * bw] = 0
    return img


def decode_frame_number(img) -> int:
    """Read back :func:`encode_frame_number` (block centres thresholded at mid-grey)."""
    h, w = img.shape[:2]
    bw = w // (BITS + 2)
    y = h // 2
    k = 0
    for b in range(BITS):
        x = (b + 1) * bw + bw // 2
        k = (k << 1) | int(img[y - 2 : y + 3, x - 2 : x + 3].mean() > 128)
    return k


def pack_tar(seq_dir, remove: bool = True, duplicate: int | None = None) -> Path:
    """Pack ``hdFace3d/`` into ``hdFace3d.tar`` (members ``hdFace3d/<name>``, sorted, fixed
    metadata so the bytes are reproducible); ``duplicate=k`` adds frame k again under
    an unpadded name (a broken archive for tests)."""
    import io
    import tarfile

    seq_dir = Path(seq_dir)
    face_dir = seq_dir / "hdFace3d"
    out = seq_dir / "hdFace3d.tar"
    with tarfile.open(out, "w", format=tarfile.USTAR_FORMAT) as tf:
        files = sorted(face_dir.iterdir())
        if duplicate is not None:
            files.append(face_dir / f"faceRecon3D_hd{duplicate:08d}.json")
        for i, p in enumerate(files):
            data = p.read_bytes()
            name = (
                f"hdFace3d/{p.name}"
                if i < len(files) - (duplicate is not None)
                else f"hdFace3d/faceRecon3D_hd{duplicate}.json"
            )
            info = tarfile.TarInfo(name)
            info.size, info.mtime, info.mode = len(data), 0, 0o644
            tf.addfile(info, io.BytesIO(data))
    if remove:
        shutil.rmtree(face_dir)
    return out


def write_videos(seq_dir, last_frame: int, size=(192, 108), cameras=None, fps: float = 29.97) -> list:
    """``hdVideos/hd_<cam>.mp4`` for each HD camera of the calibration: frames 0..last_frame,
    frame k encoding k (:func:`encode_frame_number`)."""
    import cv2

    seq_dir = Path(seq_dir)
    calib = json.loads(next(seq_dir.glob("calibration_*.json")).read_text())
    names = [c["name"] for c in calib["cameras"] if c.get("type") == "hd"]
    if cameras is not None:
        names = names[:cameras]
    (seq_dir / "hdVideos").mkdir(exist_ok=True)
    frames = [encode_frame_number(k, *size) for k in range(last_frame + 1)]
    out = []
    for name in names:
        path = seq_dir / "hdVideos" / f"hd_{name}.mp4"
        w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, tuple(size))
        if not w.isOpened():
            raise RuntimeError(f"cannot write {path} with the mp4v codec")
        for img in frames:
            w.write(img)
        w.release()
        out.append(path)
    return out


def make_video_release(
    root, sequences=("seqA", "seqB"), cameras: int = 3, frames: int = 12, people: int = 2, short: int = 3
) -> Path:
    """A small multi-sequence release made from videos: ``root/<seq>/`` with a calibration, ``hdFace3d/`` and
    ``hdVideos/hd_<cam>.mp4`` (1920x1080, frame k encoding k) for the first ``cameras`` HD cameras, frames
    0..frames-1. Every sequence after the first has videos ``short`` frames shorter than its face files (a
    video shorter than its labels). Deterministic (each sequence has its own seed)."""
    root = Path(root)
    for i, seq in enumerate(sequences):
        make_synthetic(root / seq, frames, people, cameras, seed=7 + i, first_frame=0, special=False)
        write_videos(root / seq, frames - 1 - (short if i else 0), size=(1920, 1080), cameras=cameras)
    return root


def copy_real(dst, src=REAL, frames=REAL_FRAMES) -> bool:
    """Copy the HD calibration and a few face frames of 160906_pizza1 (if available)."""
    src = Path(src)
    if not src.is_dir():
        print(f"skipping the real sample: {src} not found")
        return False
    dst = Path(dst)
    (dst / "hdFace3d").mkdir(parents=True, exist_ok=True)
    calib = json.loads((src / "calibration_160906_pizza1.json").read_text())
    calib["cameras"] = [c for c in calib["cameras"] if c.get("type") == "hd"]
    (dst / "calibration_160906_pizza1.json").write_text(json.dumps(calib, indent=1) + "\n")
    for f in frames:
        name = f"faceRecon3D_hd{f:08d}.json"
        shutil.copyfile(src / "hdFace3d" / name, dst / "hdFace3d" / name)
    return True


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--out",
        default=str(ROOT / "sample_data"),
        help="sample_data folder, or the sequence folder itself with --plain",
    )
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--people", type=int, default=3)
    ap.add_argument("--cameras", type=int, default=5)
    ap.add_argument("--seed", type=int, default=20240611)
    ap.add_argument(
        "--plain",
        action="store_true",
        help="only a plain synthetic sequence in --out (no edge cases, no real frames), e.g. for benchmarks",
    )
    ap.add_argument("--first-frame", type=int, default=100)
    ap.add_argument("--tar", action="store_true", help="pack hdFace3d/ into hdFace3d.tar (with --plain)")
    ap.add_argument("--videos", action="store_true", help="write hdVideos/hd_00_XX.mp4 (with --plain)")
    ap.add_argument("--video-size", default="192x108", help="WxH of the videos")
    a = ap.parse_args(argv)
    if a.plain:
        info = make_synthetic(a.out, a.frames, a.people, a.cameras, a.seed, first_frame=a.first_frame, special=False)
        if a.videos:
            w, h = (int(v) for v in a.video_size.lower().split("x"))
            write_videos(a.out, max(info["frames"]), (w, h))
        if a.tar:
            pack_tar(a.out)
        print(f"wrote {a.out}")
        return
    out = Path(a.out)
    synth = out / SYNTH_NAME
    if synth.exists():
        shutil.rmtree(synth)
    make_synthetic(synth, a.frames, a.people, a.cameras, a.seed)
    print(f"wrote {synth}")
    if copy_real(out / "panoptic_160906_pizza1"):
        print(f"wrote {out / 'panoptic_160906_pizza1'}")


if __name__ == "__main__":
    main()
