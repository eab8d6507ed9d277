"""BIWI Kinect Head Pose files (SPEC §8).

Files of sequence ``NN`` (01..24):

- ``hpdb/NN/frame_XXXXX_pose.txt``: three rows of a 3x3 rotation ``R``, a
  blank line, then the head centre ``c`` in mm (depth camera frame).
- ``db_annotations/NN/frame_XXXXX_pose.bin``: six little-endian float32
  values, the centre (mm), then pitch, yaw, roll in degrees.
- ``hpdb/NN/rgb.cal`` / ``depth.cal``: intrinsics K (3x3), distortion (4),
  extrinsics R (3x3) and t (mm), image width and height.

Convention (the ``biwi`` built-in system, ``configs/systems/biwi.toml``)
------------------------------------------------------------------------
The depth camera frame is OpenCV's: x to the image right, y down, z forward
(the centre of frame 01/00003, (51.9, 38.3, 881.8) mm, projects through
``depth.cal`` onto the subject's face). ``R`` is active: it turns the head
model, whose frontal pose is ``R = I`` (model x = subject's left, y = down,
z = into the head), into the camera frame. Hence, with ``F = diag(1, -1, -1)``,

    R = F @ A @ F        A = F @ R @ F   (A: 300W-LP matrix, SPEC §2)

and the ``.bin`` angles are the right-handed Z-Y-X split of the same ``R``:

    R = Rz(roll) @ Ry(yaw) @ Rx(pitch)

that is pitch = atan2(R21, R22), yaw = asin(-R20), roll = atan2(R10, R00).
For small turns yaw and roll have the 300W-LP signs (positive yaw turns the
nose to the image left, positive roll tilts the head top to the image right)
and BIWI's pitch has the opposite sign (positive = nose down). For large turns
the split order matters: over the 15677 official frames the ``.bin`` angles
(pitch negated) differ from the 300W-LP angles of the same matrix by a median
of 1 degree but by up to 83 (pitch), 48 (yaw) and 77 (roll) degrees, so they
must be converted, never reused. Hopenet's BIWI reader (transpose, then negate
yaw and roll) returns exactly the 300W-LP angles of ``A``.

Evidence: ``pose.txt`` and ``.bin`` overlap on no frame (sequence 01's
``.bin`` starts at frame 4). The Z-Y-X split of frame 3's matrix, (-7.71, 3.05,
-1.99), is closer to the ``.bin`` of frames 4-10, mean (-7.72, 3.45, -2.50),
sd (0.11, 0.18, 0.15), than the X-Y-Z split (-7.61, 3.29, -1.57) and far from
any reading of ``R.T``; the tests check this. The yaw sign was also checked by
eye on frames 01/166 (yaw -1.4) and 01/175 (yaw +6.6): the nose moves to the
image left.
"""

from __future__ import annotations

import re
import tarfile
from pathlib import Path

import numpy as np

from ..errors import HpeError
from ..rotation import canonical_to_labels, get_system
from ..rotation.columns import conversion_columns
from .fields import distortion_problem, frame_number_problem, intrinsics_problem, member_problem, rotation_problem

#: the rotation system of BIWI's matrices and ``.bin`` angles
BIWI_SYSTEM = "biwi"
#: largest ||R R^T - I||_F accepted from a pose.txt (its 6 printed digits give ~1e-6)
POSE_TXT_TOL = 1e-4

#: head centres farther than this (mm) are not a Kinect recording (its depth range is 0.5-4.5 m)
MAX_CENTRE_MM = 1e4
#: largest |pitch|, |yaw|, |roll| (degrees) of a Z-Y-X split (atan2, asin, atan2), with float32's slack
ANGLE_LIMITS = (180.001, 90.001, 180.001)
_NAME = re.compile(r"(?:^|/)(\d+)/frame_(\d+)_pose\.(txt|bin)$")
CENTRE_COLS = ["center_x", "center_y", "center_z"]


def _numbers(path, text: str, expected: int, what: str) -> np.ndarray:
    try:
        v = np.array(text.split(), dtype=np.float64)
    except ValueError:
        raise HpeError(f"{path}: expected {expected} numbers ({what}), found a non-number") from None
    if v.size != expected:
        raise HpeError(f"{path}: expected {expected} numbers ({what}), got {v.size}")
    if not np.isfinite(v).all():
        raise HpeError(f"{path}: expected finite numbers ({what}), got {v[~np.isfinite(v)][0]}")
    return v


def nearest_rotation(M) -> np.ndarray:
    """Closest proper rotation (Frobenius norm) to each ``(..., 3, 3)`` matrix, by SVD."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    d = np.sign(np.linalg.det(U @ Vt))
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def read_pose_txt(path):
    """Read one ``frame_XXXXX_pose.txt``.

    Returns
    -------
    R : ndarray (3, 3)
        BIWI rotation (system ``biwi``), projected onto the nearest rotation
        (the file's 6 digits leave ~1e-6 of non-orthogonality).
    centre : ndarray (3,)
        Head centre in mm, depth camera frame (x right, y down, z forward).
    """
    path = Path(path)
    text = _read_text(path, "BIWI pose file")
    v = _numbers(path, text, 12, "3x3 rotation then centre")
    M = v[:9].reshape(3, 3)
    err = np.linalg.norm(M @ M.T - np.eye(3))
    if err > POSE_TXT_TOL or np.linalg.det(M) < 0:
        raise HpeError(
            f"{path}: expected a rotation matrix, got ||R R^T - I|| = {err:.3g}, det = {np.linalg.det(M):.4g}"
        )
    why = centre_problem(v[9:])
    if why:
        raise HpeError(f"{path}: {why}")
    return nearest_rotation(M), v[9:]


def centre_problem(c) -> str:
    """'' for a head centre (mm, depth camera) in front of the camera and nearer than :data:`MAX_CENTRE_MM`."""
    c = np.asarray(c, dtype=np.float64)
    if not (c[2] > 0 and np.abs(c).max() <= MAX_CENTRE_MM):
        return (
            f"head centre: expected a point in front of the camera (z > 0) within {MAX_CENTRE_MM:g} mm, "
            f"got ({c[0]:g}, {c[1]:g}, {c[2]:g}) mm"
        )
    return ""


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise HpeError(f"{path}: cannot read {what} ({exc.__class__.__name__})") from None


def _decode_bin(path, data: bytes) -> np.ndarray:
    if len(data) != 24:
        raise HpeError(f"{path}: expected 24 bytes (6 float32), got {len(data)}")
    v = np.frombuffer(data, dtype="<f4").astype(np.float64)
    if not np.isfinite(v).all():
        raise HpeError(f"{path}: expected finite values, got {v.tolist()}")
    why = centre_problem(v[:3])
    if why:
        raise HpeError(f"{path}: {why}")
    for name, a, lim in zip(("pitch", "yaw", "roll"), v[3:], ANGLE_LIMITS):
        if abs(a) > lim:
            raise HpeError(f"{path}: {name}: expected degrees within +-{lim:.0f} (a Z-Y-X split), got {a:g}")
    return v


def read_pose_bin(path) -> np.ndarray:
    """Read one ``frame_XXXXX_pose.bin``: ``[cx, cy, cz (mm), pitch, yaw, roll (deg, biwi system)]``."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise HpeError(f"{path}: cannot read BIWI annotation ({exc.__class__.__name__})") from None
    return _decode_bin(path, data)


def read_calibration(path) -> dict:
    """Read ``rgb.cal`` or ``depth.cal``.

    Returns
    -------
    dict
        ``K`` (3, 3) pixels, ``dist`` (4,), ``R`` (3, 3) and ``t`` (3,) mm
        (the camera's extrinsics as stored; ``depth.cal`` has R = I, t = 0),
        ``size`` (width, height) pixels.
    """
    path = Path(path)
    text = _read_text(path, "BIWI calibration")
    v = _numbers(path, text, 27, "K 3x3, 4 distortion, R 3x3, t 3, width height")
    w, h = v[25], v[26]
    if not (w > 0 and h > 0 and float(w).is_integer() and float(h).is_integer() and max(w, h) <= 1e5):
        raise HpeError(f"{path}: width, height: expected positive whole numbers of pixels, got {w:g}, {h:g}")
    K, dist, R, t = v[:9].reshape(3, 3), v[9:13], v[13:22].reshape(3, 3), v[22:25]
    for why in (
        intrinsics_problem(K, w, h),
        distortion_problem(dist, K, w, h, "distortion"),
        rotation_problem(R, "R", POSE_TXT_TOL),
    ):
        if why:
            raise HpeError(f"{path}: {why}")
    if np.abs(t).max() > MAX_CENTRE_MM:
        raise HpeError(f"{path}: t: expected a translation within {MAX_CENTRE_MM:g} mm, got {t.tolist()}")
    return {"K": K, "dist": dist, "R": R, "t": t, "size": (int(w), int(h))}


def _parse_name(name: str, where=None):
    m = _NAME.search(name.replace("\\", "/"))
    if m is None:
        return None
    if frame_number_problem(m.group(2)):
        raise HpeError(f"{where or name}: {frame_number_problem(m.group(2))}")
    return m.group(1), int(m.group(2)), m.group(3)


def _refuse_duplicates(keys, names, where) -> None:
    """Two files (or members) that are the same frame of the same sequence: an error naming both."""
    seen: dict = {}
    for key, name in zip(keys, names):
        if key in seen:
            raise HpeError(
                f"{where}: {seen[key]} and {name} are both sequence {key[0]} frame {key[1]}; keep one "
                "(its rows would be duplicated)"
            )
        seen[key] = name


def labels_table(files, sequences, frames, centres, R=None, angles=None, system=BIWI_SYSTEM):
    """Assemble the label table from stacked arrays (matrices or ``.bin`` angles).

    Columns: ``file, sequence, frame``, the conversion columns of ``system``
    (``pitch, yaw, roll`` degrees, ``pitch_2..roll_2``, ``r00..r22``,
    ``gimbal_lock, roundtrip_err``), then ``center_x, center_y, center_z`` (mm).
    """
    import pandas as pd

    biwi = get_system(BIWI_SYSTEM)
    stored = np.asarray(R, dtype=np.float64) if R is not None else biwi.from_angles(angles)
    conv = canonical_to_labels(biwi.to_canonical(stored.reshape(-1, 3, 3)), system)
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    cols = {"file": list(files), "sequence": list(sequences), "frame": np.asarray(frames, dtype=np.int64)}
    cols.update(conversion_columns(conv))
    cols.update({c: centres[:, n] for n, c in enumerate(CENTRE_COLS)})
    return pd.DataFrame(cols)


def read_biwi(path, system=BIWI_SYSTEM, kind: str = "auto", bad: list | None = None):
    """Read BIWI pose files into the label table.

    Parameters
    ----------
    path : str or Path
        A folder searched recursively for ``NN/frame_XXXXX_pose.txt`` /
        ``.bin`` (``hpdb/``, ``db_annotations/`` or one sequence folder), a
        single pose file, or ``db_annotations.tgz`` (read without extracting).
    system : str or RotationSystem
        System of the output labels: ``biwi`` (the ``.bin`` angles; default)
        or any other, e.g. ``300w_lp``.
    kind : {"auto", "txt", "bin"}
        Which files of a folder to read; ``auto`` takes ``pose.txt`` when the
        folder has any, else ``.bin``.
    bad : list, optional
        Collect frames whose pose file is unreadable or invalid instead of
        raising: one :func:`frame_reject` dict per frame (``file``,
        ``sequence``, ``frame``, ``reason``, ``message``); the table holds the
        other frames. Without it the first such file raises ``HpeError``.
        Names, duplicates and archives that cannot be read stay errors.

    Returns
    -------
    pandas.DataFrame
        See :func:`labels_table`; sorted by sequence then frame; ``file`` is
        relative to ``path``.
    """
    path = Path(path)
    if path.is_file() and path.name.endswith((".tgz", ".tar.gz", ".tar")):
        return read_biwi_tgz(path, system, bad=bad)
    if path.is_file():
        files, base = [path], path.parent
    elif path.is_dir():
        base = path
        txt = sorted(path.rglob("frame_*_pose.txt"))
        binf = sorted(path.rglob("frame_*_pose.bin"))
        if kind == "txt" or (kind == "auto" and txt):
            files = txt
        else:
            files = binf
    else:
        raise HpeError(f"{path}: no such file or folder")
    recs = []
    for f in files:
        parsed = _parse_name(f.resolve().as_posix(), f)  # the sequence is the parent folder's name
        if parsed is None:
            raise HpeError(f"{f}: expected a name like NN/frame_XXXXX_pose.txt or .bin")
        recs.append((f, *parsed))
    if not recs:
        raise HpeError(f"{path}: no BIWI frame_XXXXX_pose.txt or .bin files found")
    recs.sort(key=lambda r: (r[1], r[2]))
    kinds = {r[3] for r in recs}
    if len(kinds) > 1:
        raise HpeError(f"{path}: expected one kind of pose file, got both .txt and .bin (use kind=)")
    names = [r[0].relative_to(base).as_posix() for r in recs]
    _refuse_duplicates([(r[1], r[2]) for r in recs], names, path)
    reader = read_pose_txt if kinds == {"txt"} else read_pose_bin
    keep, values = [], []
    for k, r in enumerate(recs):
        try:
            values.append(reader(r[0]))
        except HpeError as exc:
            if bad is None:
                raise
            bad.append(frame_reject(names[k], r[1], r[2], exc, r[0]))
            continue
        keep.append(k)
    _all_rejected(path, keep, bad)
    names, seqs, frames = [names[k] for k in keep], [recs[k][1] for k in keep], [recs[k][2] for k in keep]
    if kinds == {"txt"}:
        return labels_table(
            names, seqs, frames, np.stack([p[1] for p in values]), R=np.stack([p[0] for p in values]), system=system
        )
    vals = np.stack(values)
    return labels_table(names, seqs, frames, vals[:, :3], angles=vals[:, 3:], system=system)


def frame_reject(name, sequence, frame, exc, where) -> dict:
    """A frame set aside: its ``file`` (as in the label table), ``sequence``, ``frame``, the ``reason`` (the
    error without its ``where: `` prefix) and the whole one-line ``message`` (``FILE: reason``)."""
    msg = str(exc)
    head = f"{where}: "
    return {"file": name, "sequence": sequence, "frame": int(frame), "reason": msg.removeprefix(head), "message": msg}


def _all_rejected(path, keep, bad) -> None:
    if not keep and bad:
        raise HpeError(f"{bad[0]['message']}; no readable BIWI pose file in {path} ({len(bad)} rejected)")


def read_biwi_tgz(path, system=BIWI_SYSTEM, bad: list | None = None):
    """Read the official ``db_annotations.tgz`` (``NN/frame_XXXXX_pose.bin`` members) without extracting it.

    Members that are not pose files are skipped; ``file`` is the member name.
    ``bad``: as for :func:`read_biwi` (a member of the wrong size or with
    invalid values is set aside there instead of raising).
    """
    path = Path(path)
    names, seqs, frames, vals = [], [], [], []
    seen_members: set = set()
    try:
        with tarfile.open(path, "r:*") as tf:
            for m in tf:
                if member_problem(m.name):
                    raise HpeError(f"{path}: member {m.name!r}: refused: {member_problem(m.name)}")
                if not m.isfile():
                    continue
                parsed = _parse_name(m.name, f"{path}:{m.name}")
                if parsed is None or parsed[2] != "bin":
                    continue
                if m.name in seen_members:
                    raise HpeError(
                        f"{path}: member {m.name} appears twice in the archive (its rows would be "
                        "duplicated); repack it with one copy"
                    )
                seen_members.add(m.name)
                try:
                    if m.size != 24:  # checked from the header, before reading the member
                        raise HpeError(f"{path}:{m.name}: expected 24 bytes (6 float32), got {m.size}")
                    vals.append(_decode_bin(f"{path}:{m.name}", tf.extractfile(m).read(25)))
                except HpeError as exc:
                    if bad is None:
                        raise
                    bad.append(frame_reject(m.name, parsed[0], parsed[1], exc, f"{path}:{m.name}"))
                    continue
                names.append(m.name)
                seqs.append(parsed[0])
                frames.append(parsed[1])
    except (tarfile.TarError, OSError, EOFError) as exc:
        raise HpeError(f"{path}: not a readable tar archive ({' '.join(str(exc).split())[:120]})") from None
    _all_rejected(path, vals, bad)
    if not vals:
        raise HpeError(f"{path}: no NN/frame_XXXXX_pose.bin members found")
    _refuse_duplicates(list(zip(seqs, frames)), names, path)
    order = sorted(range(len(names)), key=lambda k: (seqs[k], frames[k]))
    v = np.stack(vals)[order]
    return labels_table(
        [names[k] for k in order],
        [seqs[k] for k in order],
        [frames[k] for k in order],
        v[:, :3],
        angles=v[:, 3:],
        system=system,
    )


# ---------------------------------------------------------------------------------------------------------------
# RGB camera, head boxes, protocols and sequence splits
# ---------------------------------------------------------------------------------------------------------------
#: diameter of the sphere taken as the head when boxes are projected (mm); an adult head is about 150 mm wide
#: and 200 mm from chin to crown, so the box holds the whole head with a little margin
HEAD_SIZE_MM = 200.0
#: BIWI's depth intrinsics (every sequence's depth.cal): used when no depth.cal is found
DEPTH_K = np.array([[575.816, 0.0, 320.0], [0.0, 575.816, 240.0], [0.0, 0.0, 1.0]])
#: Hopenet / 6DRepNet keep test samples whose three 300W-LP angles lie within +-99 degrees
PROTOCOLS = ("all", "hopenet-99")
BOX_COLS = ["bbox_x", "bbox_y", "bbox_w", "bbox_h"]


def to_rgb_camera(R, centres, cal):
    """Move BIWI labels from the depth camera into the RGB camera with ``rgb.cal``'s extrinsics.

    ``rgb.cal`` stores ``R_c, t_c`` with ``X_rgb = R_c @ X_depth + t_c`` (mm).
    Checked on the real frame 01/00003: the head centre projects onto the
    bridge of the nose with this direction (341.7, 274.6) and 22 px off the
    face's midline with the inverse one. Both cameras are OpenCV frames, so
    the ``biwi`` rotation becomes ``R_c @ R``.

    Parameters
    ----------
    R : ndarray (N, 3, 3)
        ``biwi`` matrices in the depth camera.
    centres : ndarray (N, 3)
        Head centres in mm, depth camera.
    cal : dict
        :func:`read_calibration` of ``rgb.cal``.
    """
    Rc, tc = np.asarray(cal["R"], dtype=np.float64), np.asarray(cal["t"], dtype=np.float64)
    Rc = nearest_rotation(Rc)  # printed with 6 digits
    return Rc @ np.asarray(R, dtype=np.float64), np.asarray(centres, dtype=np.float64) @ Rc.T + tc


def head_boxes(centres, K, dist=None, head_size_mm: float = HEAD_SIZE_MM):
    """Square head boxes from projecting a sphere of diameter ``head_size_mm`` around each head centre.

    The box is centred on the projected centre ``(u, v)`` (OpenCV projection
    with ``K`` and the 4 distortion coefficients) and its side is the
    diameter of the sphere's image, ``2 f r / sqrt(|c|^2 - r^2)`` with
    ``r = head_size_mm / 2`` and ``f = (fx + fy) / 2`` (exact for a sphere on
    the optical axis, within 1 % over BIWI's field of view).

    Returns
    -------
    boxes : ndarray (N, 4)
        ``bbox_x, bbox_y, bbox_w, bbox_h`` in pixels (top-left corner, size).
    uv : ndarray (N, 2)
        The projected centres.
    """
    import cv2

    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    K = np.asarray(K, dtype=np.float64)
    d = np.zeros(4) if dist is None else np.asarray(dist, dtype=np.float64)
    uv = np.full((len(c), 2), np.nan)
    front = c[:, 2] > 0
    if front.any():
        pts, _ = cv2.projectPoints(c[front].reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, d)
        uv[front] = pts.reshape(-1, 2)
    r = head_size_mm / 2.0
    dist2 = np.einsum("ij,ij->i", c, c) - r * r
    f = (K[0, 0] + K[1, 1]) / 2.0
    with np.errstate(invalid="ignore", divide="ignore"):
        side = np.where(front & (dist2 > 0), 2.0 * f * r / np.sqrt(np.maximum(dist2, 1e-300)), np.nan)
    boxes = np.stack([uv[:, 0] - side / 2, uv[:, 1] - side / 2, side, side], axis=1)
    return boxes, uv


def _find_calibration(root: Path, sequence: str, name: str):
    for cand in (root / sequence / name, root / "hpdb" / sequence / name, root / name):
        if cand.is_file():
            return cand
    hit = next((p for p in root.rglob(name) if p.parent.name == sequence), None)
    return hit


def read_biwi_camera(
    path,
    camera: str = "depth",
    calibration=None,
    head_size_mm: float = HEAD_SIZE_MM,
    system=BIWI_SYSTEM,
    bad: list | None = None,
):
    """BIWI labels in the depth or RGB camera, with head-centre boxes.

    Parameters
    ----------
    path : str or Path
        As for :func:`read_biwi` (``hpdb/``, one sequence, ``db_annotations``
        or its ``.tgz``).
    camera : {"depth", "rgb"}
        ``rgb`` applies each sequence's ``rgb.cal`` (:func:`to_rgb_camera`)
        to the matrices and centres, and projects the boxes with its
        intrinsics; ``depth`` keeps the labels and uses ``depth.cal`` (or
        BIWI's 575.816 px, (320, 240) when absent).
    calibration : str or Path, optional
        Folder holding ``NN/rgb.cal`` (and ``depth.cal``), e.g. ``hpdb/``;
        default ``path`` (or its folder).
    head_size_mm : float
        Diameter of the head sphere for the boxes (:data:`HEAD_SIZE_MM`).
    bad : list, optional
        Collects the frames whose pose file is unreadable or invalid
        (:func:`read_biwi`); a bad calibration file stays an error.

    Returns
    -------
    pandas.DataFrame
        :func:`labels_table` columns in ``system`` (centres in the chosen
        camera), then ``camera``, ``image`` (``NN/frame_XXXXX_rgb.png`` or
        ``_depth.bin``), ``center_u, center_v`` and ``bbox_x, bbox_y,
        bbox_w, bbox_h`` (pixels). ``attrs["system"]`` is ``system``'s name.
    """

    if camera not in ("depth", "rgb"):
        raise HpeError(f"--camera: expected depth or rgb, got {camera!r}")
    path = Path(path)
    base = read_biwi(path, system=BIWI_SYSTEM, bad=bad)
    R = np.array(base[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy(), dtype=np.float64).reshape(-1, 3, 3)
    centres = np.array(base[CENTRE_COLS].to_numpy(), dtype=np.float64)
    seqs = base["sequence"].astype(str).to_numpy()
    root = Path(calibration) if calibration is not None else (path if path.is_dir() else path.parent)
    K_rows = np.repeat(DEPTH_K[None], len(base), axis=0)
    dist_rows = np.zeros((len(base), 4))
    for seq in sorted(set(seqs.tolist())):
        rows = seqs == seq
        cal_name = "rgb.cal" if camera == "rgb" else "depth.cal"
        calp = _find_calibration(root, seq, cal_name)
        if calp is None:
            if camera == "rgb":
                raise HpeError(
                    f"{root}: no {seq}/rgb.cal for sequence {seq} (--camera rgb needs hpdb/NN/rgb.cal; "
                    "point --calibration at the hpdb folder)"
                )
            continue
        cal = read_calibration(calp)
        if camera == "rgb":
            R[rows], centres[rows] = to_rgb_camera(R[rows], centres[rows], cal)
        K_rows[rows] = cal["K"]
        dist_rows[rows] = cal["dist"]
    out = labels_table(
        base["file"].tolist(), seqs.tolist(), base["frame"].to_numpy(), centres, R=R, system=get_system(system)
    )
    boxes = np.full((len(out), 4), np.nan)
    uv = np.full((len(out), 2), np.nan)
    for key in {(tuple(k.ravel()), tuple(d)) for k, d in zip(K_rows, dist_rows)}:
        rows = np.all(K_rows.reshape(-1, 9) == np.array(key[0]), axis=1) & np.all(dist_rows == np.array(key[1]), axis=1)
        boxes[rows], uv[rows] = head_boxes(
            centres[rows], np.array(key[0]).reshape(3, 3), np.array(key[1]), head_size_mm
        )
    suffix = "rgb.png" if camera == "rgb" else "depth.bin"
    out["camera"] = camera
    out["image"] = [f"{s}/frame_{int(f):05d}_{suffix}" for s, f in zip(out["sequence"], out["frame"])]
    out["center_u"], out["center_v"] = uv[:, 0], uv[:, 1]
    for i, c in enumerate(BOX_COLS):
        out[c] = boxes[:, i]
    out.attrs["system"] = get_system(system).name
    return out


def protocol_mask(frame, protocol: str = "all"):
    """Rows kept by a published BIWI test protocol.

    ``all``: every frame. ``hopenet-99``: the three 300W-LP angles of the
    label within +-99 degrees (the filter Hopenet's and 6DRepNet's
    ``datasets.py`` apply to their test lists; over the 15,677 official
    frames it removes none). FSA-Net's "protocol 1" list keeps the frames
    where MTCNN found a face (confidence > 0.90, ``data/TYY_create_db_biwi.py``);
    that list depends on the detector run and is not published, so it is
    not offered.
    """

    if protocol not in PROTOCOLS:
        raise HpeError(f"--protocol: expected one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    if protocol == "all":
        return np.ones(len(frame), dtype=bool)
    R = frame[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)
    system = get_system(frame.attrs.get("system", BIWI_SYSTEM))
    conv = canonical_to_labels(system.to_canonical(R), get_system("300w_lp"))
    return np.all(np.abs(conv.primary) <= 99.0, axis=1)


def sequence_split(sequences, fractions=(0.7, 0.3), seed: int = 0, names=("train", "test")) -> dict:
    """Deterministic split of BIWI sequences (never one sequence in two splits).

    The sorted unique sequences are shuffled with ``numpy.random.default_rng(seed)``
    and cut at the cumulative fractions (rounded, each split at least one
    sequence when there are enough). FSA-Net's 70/30 protocol
    (``data/TYY_create_db_biwi_70_30.py``) puts 16 of the 24 sequences in
    training with an unseeded ``np.random.permutation``, so its lists cannot
    be recovered; ``fractions=(16/24, 8/24)`` gives the same sizes, and the
    lists written out make any split reproducible.

    Returns
    -------
    dict
        split name -> sorted list of sequence names.
    """
    fr = np.asarray(fractions, dtype=np.float64)
    if fr.ndim != 1 or fr.size < 2 or (fr < 0).any() or not np.isclose(fr.sum(), 1.0):
        raise HpeError(f"--split: expected fractions >= 0 that sum to 1, got {','.join(f'{f:g}' for f in fr)}")
    if len(names) != fr.size:
        names = (
            tuple(["train", "val", "test"][: fr.size]) if fr.size <= 3 else tuple(f"split{i}" for i in range(fr.size))
        )
    uniq = sorted({str(s) for s in sequences})
    perm = [uniq[i] for i in np.random.default_rng(seed).permutation(len(uniq))]
    cuts = np.round(np.cumsum(fr) * len(uniq)).astype(int)
    cuts[-1] = len(uniq)
    out, start = {}, 0
    for name, end in zip(names, cuts):
        out[name] = sorted(perm[start:end])
        start = end
    return out
