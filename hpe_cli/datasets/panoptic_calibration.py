"""CMU Panoptic Studio calibration (``calibration_<seq>.json``), checked camera by camera (SPEC §6).

Re-exported by :mod:`hpe_cli.datasets.panoptic` (``pan.read_calibration``, ``pan.Cameras``). Each camera
is checked as what it is (:func:`_camera`): a non-empty, unique name usable as a path part; ``K`` a
pinhole matrix with positive focal lengths and the principal point inside the image; ``R`` a rotation;
``t`` finite; ``distCoef`` OpenCV's model within what a real lens does over this image
(:func:`hpe_cli.datasets.fields.distortion_problems`, bound stated there); ``resolution``, ``panel``,
``node`` integers. Failures are one line: ``FILE: camera I (NAME): FIELD: expected X, got Y``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import HpeError
from .fields import as_int, describe, distortion_problems, intrinsics_problem, numbers_or_why
from .panoptic_json import load_panoptic_json

#: camera names become path parts: letters, digits, '_', '-', '.' only (no '..', '/', NUL)
NAME_RE = re.compile(r"^[A-Za-z0-9_.-]+$")
#: landmarks (and camera positions) farther than this from the origin (cm) are not in a 5-m dome
ABSURD = 1e6
CAMERA_TYPES = ("hd", "vga", "kinect-color")


@dataclass
class Cameras:
    """C calibrated cameras, as arrays.

    Attributes
    ----------
    names : ndarray of str (C,)
        ``"00_08"`` ...
    types : ndarray of str (C,)
        ``"hd"``, ``"vga"`` or ``"kinect-color"``.
    panel, node : ndarray of int (C,)
    width, height : ndarray of int (C,)
        ``resolution`` in pixels.
    K : ndarray (C, 3, 3)
    dist : ndarray (C, 5)
        ``k1, k2, p1, p2, k3`` (OpenCV); missing trailing values are 0.
    R : ndarray (C, 3, 3)
        World -> camera rotation (``R @ X + t``; OpenCV camera frame).
    t : ndarray (C, 3)
        World -> camera translation, cm.
    source : str
        The calibration file.
    """

    names: np.ndarray
    types: np.ndarray
    panel: np.ndarray
    node: np.ndarray
    width: np.ndarray
    height: np.ndarray
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    source: str = ""

    def __len__(self) -> int:
        return len(self.names)

    def take(self, idx) -> Cameras:
        idx = np.asarray(idx, dtype=np.intp)
        return Cameras(
            *(
                getattr(self, f)[idx]
                for f in ("names", "types", "panel", "node", "width", "height", "K", "dist", "R", "t")
            ),
            source=self.source,
        )

    def select(self, spec="hd") -> Cameras:
        """Cameras by type (``hd``, ``vga``, ``kinect-color``, ``all``) or by names.

        ``spec`` is a type, a list of names, or a comma-separated string of
        them (``"00_00,00_08"``); order follows ``spec`` for names.
        """
        items = [s.strip() for s in (spec.split(",") if isinstance(spec, str) else spec) if str(s).strip()]
        if not items:
            raise HpeError(f"{self.source}: expected camera names or a camera type, got nothing")
        chosen: list = []
        index = {n: i for i, n in enumerate(self.names)}
        for item in items:
            if item == "all":
                chosen += list(range(len(self)))
            elif item in CAMERA_TYPES:
                chosen += [i for i, t in enumerate(self.types) if t == item]
            elif item in index:
                chosen.append(index[item])
            else:
                known = ", ".join(list(self.names[:4]) + ["..."]) if len(self) > 4 else ", ".join(self.names)
                raise HpeError(
                    f"{self.source}: expected a camera name ({known}) or a type "
                    f"({', '.join(CAMERA_TYPES)}, all), got {item!r}"
                )
        chosen = list(dict.fromkeys(chosen))
        if not chosen:
            raise HpeError(f"{self.source}: no camera matches {spec!r}")
        return self.take(chosen)


def read_calibration(path, cameras="all") -> Cameras:
    """Read ``calibration_<seq>.json``.

    Parameters
    ----------
    path : str or Path
    cameras : str or list
        Passed to :meth:`Cameras.select` (``"all"`` keeps every camera).

    Returns
    -------
    Cameras
    """

    path = Path(path)
    data = load_panoptic_json(path)
    cams = data.get("cameras") if isinstance(data, dict) else None
    if not isinstance(cams, list):
        got = (
            type(data).__name__
            if not isinstance(data, dict)
            else "keys " + ", ".join(repr(k)[:30] for k in list(data)[:6])
        )
        raise HpeError(f"{path}: expected an object with a 'cameras' list, got {got}")
    cols = {k: [] for k in ("names", "types", "panel", "node", "width", "height", "K", "dist", "R", "t")}
    seen: dict = {}
    for i, cam in enumerate(cams):
        rec = _camera(cam, i, path)
        name = rec[0]
        if name in seen:
            raise HpeError(f"{path}: camera {seen[name]} and camera {i} are both named {name!r}")
        seen[name] = i
        for key, value in zip(cols, rec):
            cols[key].append(value)
    if not cols["names"]:
        raise HpeError(f"{path}: the calibration lists no cameras")

    bad = distortion_problems(
        np.stack(cols["dist"]), np.stack(cols["K"]), np.asarray(cols["width"]), np.asarray(cols["height"])
    )  # what the lens model does inside each image
    for i, why in enumerate(bad):
        if why:
            raise HpeError(f"{path}: camera {i} ({cols['names'][i]}): {why}")
    out = Cameras(
        names=np.asarray(cols["names"], dtype=object),
        types=np.asarray(cols["types"], dtype=object),
        panel=np.asarray(cols["panel"], dtype=np.int64),
        node=np.asarray(cols["node"], dtype=np.int64),
        width=np.asarray(cols["width"], dtype=np.int64),
        height=np.asarray(cols["height"], dtype=np.int64),
        K=np.stack(cols["K"]),
        dist=np.stack(cols["dist"]),
        R=np.stack(cols["R"]),
        t=np.stack(cols["t"]),
        source=str(path),
    )
    return out if cameras == "all" else out.select(cameras)


def _camera(cam, i: int, path) -> tuple:
    """One calibration entry checked field by field: ``(name, type, panel, node, width, height, K, dist, R, t)``.

    Every failure is ``FILE: camera I (NAME): FIELD ...``: the name (a non-empty string of letters,
    digits, ``_ - .``; a null name is refused, not read as "None"), ``type`` (a string), ``panel`` and
    ``node`` (integers), ``resolution`` (two positive integers), ``K`` (pinhole, fx, fy > 0, principal
    point inside the image), ``R`` (a rotation), ``t`` (finite, cm), ``distCoef`` (OpenCV's model within
    what a real lens does over this image, :func:`hpe_cli.datasets.fields.distortion_problem`).
    """

    where = f"{path}: camera {i}"
    if not isinstance(cam, dict):
        raise HpeError(f"{where}: expected an object with name, K, R, t, distCoef, resolution, got {describe(cam)}")
    for key in ("name", "K", "R", "t"):
        if key not in cam:
            if key != "name":
                where = f"{path}: camera {i} ({cam.get('name')})"
            raise HpeError(f"{where}: missing key {key!r}")
    name = cam["name"]
    if not isinstance(name, str) or not NAME_RE.match(name) or name in (".", ".."):
        raise HpeError(
            f"{where}: name: expected a camera name of letters, digits, '_', '-' or '.', got "
            f"{describe(name) if not isinstance(name, str) else repr(name)} (names become image paths)"
        )
    where = f"{path}: camera {i} ({name})"

    def numbers(key, shape, size=None):
        arr, why = numbers_or_why(cam[key], key, None)
        if arr is None:
            raise HpeError(f"{where}: {why}")
        n = int(np.prod(shape)) if size is None else size
        if arr.size != n:
            raise HpeError(f"{where}: expected {key} with {n} values {shape}, got shape {arr.shape}")
        if not np.isfinite(arr).all():
            raise HpeError(f"{where}: expected finite K, R, t and distCoef, got NaN or inf in {key}")
        return arr.reshape(shape)

    K, R, t = numbers("K", (3, 3)), numbers("R", (3, 3)), numbers("t", (3,))
    d, why = numbers_or_why(cam.get("distCoef", [0.0] * 5), "distCoef")
    if d is None:
        raise HpeError(f"{where}: {why}")
    d = d.reshape(-1)
    if d.size not in (4, 5, 8, 12, 14):
        raise HpeError(f"{where}: expected 5 distCoef values (k1, k2, p1, p2, k3), got {d.size}")
    if not np.isfinite(d).all():
        raise HpeError(f"{where}: expected finite K, R, t and distCoef, got NaN or inf in distCoef")
    if d.size > 5 and np.any(d[5:] != 0):
        raise HpeError(
            f"{where}: distCoef: only the 5-coefficient OpenCV model is supported, got {d.size} non-zero coefficients"
        )
    d = np.concatenate([d, np.zeros(5)])[:5]
    res = cam.get("resolution")
    if not isinstance(res, (list, tuple)) or len(res) != 2:
        raise HpeError(f"{where}: expected resolution [width, height], got {describe(res)}")
    (w, why_w), (h, why_h) = as_int(res[0]), as_int(res[1])
    if w is None or h is None:
        raise HpeError(f"{where}: resolution: expected [width, height] as integers, {why_w or why_h}")
    if w <= 0 or h <= 0:
        raise HpeError(f"{where}: expected a positive resolution, got {w}x{h}")
    if not (np.abs(R @ R.T - np.eye(3)).max() <= 1e-4 and np.linalg.det(R) > 0):
        raise HpeError(
            f"{where}: expected R to be a rotation (orthonormal, det +1), got det "
            f"{np.linalg.det(R):.6g}, ||R R^T - I|| = {np.linalg.norm(R @ R.T - np.eye(3)):.3g}"
        )
    if not (K[0, 0] > 0 and K[1, 1] > 0) or K[2, 2] != 1 or np.any(K[2, :2] != 0) or K[1, 0] != 0:
        raise HpeError(f"{where}: expected K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {K.tolist()}")
    if not (0 <= K[0, 2] <= w and 0 <= K[1, 2] <= h):
        raise HpeError(f"{where}: {intrinsics_problem(K, w, h)}")
    if not (np.abs(t) < ABSURD).all():
        raise HpeError(f"{where}: t: expected a translation in cm smaller than {ABSURD:g}, got {t.tolist()}")
    typ = cam.get("type", "")
    if not isinstance(typ, str):
        raise HpeError(f"{where}: type: expected a string (hd, vga, kinect-color), got {describe(typ)}")
    ids = []
    for key in ("panel", "node"):
        v, why = as_int(cam.get(key, -1), -(2**31), 2**31 - 1)
        if v is None:
            raise HpeError(f"{where}: {key}: expected an integer, {why}")
        ids.append(v)
    return name, typ, ids[0], ids[1], w, h, K, d, R, t
