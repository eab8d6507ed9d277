"""WHENet's ``annotation.txt``: one comma-separated line per head crop.

WHENet's ``prepare_images.py`` (Ascend-Research/HeadPoseEstimation-WHENet)
appends, for every head it keeps, the line

    <image>,<yaw>,<pitch>,<roll>

where ``<image>`` is the crop's path relative to the dataset folder
(``<sequence>/<cam>_<person>_<frame>.jpg``) and the three angles are degrees
written with Python's ``str(float)``, in the order **yaw, pitch, roll** (not
the role order used everywhere else in hpe). There is no header, no box and
no landmark: WHENet's images are already crops of the head box. Its angles are
the ``whenet`` system (300W-LP matrix, yaw in (-180, 180], |pitch| and |roll|
< 90).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError
from .writers import AtomicFile

#: column order of one line, as WHENet writes it
WHENET_FIELDS = ("image", "yaw", "pitch", "roll")


def whenet_lines(frame, path="<annotation.txt>") -> list:
    """The ``annotation.txt`` lines (with their newline) of a label table."""
    missing = [c for c in WHENET_FIELDS if c not in frame.columns]
    if missing:
        raise HpeError(f"{path}: expected columns {', '.join(missing)} in the label table")
    images = frame["image"].astype(str).to_numpy()
    if images.size:
        unsafe = np.char.find(images.astype(str), ",") >= 0
        for ch in ("\n", "\r"):
            unsafe |= np.char.find(images.astype(str), ch) >= 0
        if unsafe.any():
            k = int(np.flatnonzero(unsafe)[0])
            raise HpeError(f"{path}: row {k}: expected an image path without commas or line breaks, "
                           f"got {images[k]!r}")
    cols = []
    for c in WHENET_FIELDS[1:]:
        v = frame[c].to_numpy(dtype=np.float64, na_value=np.nan)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise HpeError(f"{path}: row {bad[0]}: expected a finite {c}, got {v[bad[0]]}")
        cols.append(v.tolist())
    # str(float) is the shortest repr that round-trips, exactly what WHENet writes
    return [f"{im},{y!s},{p!s},{r!s}\n" for im, y, p, r in zip(images.tolist(), *cols)]


def write_whenet(frame, path, overwrite: bool = False) -> Path:
    """Write a label table as WHENet ``annotation.txt`` lines, atomically.

    Parameters
    ----------
    frame : pandas.DataFrame
        Needs ``image`` (path, written as is) and ``pitch, yaw, roll``
        (degrees). Other columns, such as the box, are not part of the format
        and are ignored.
    path : str or Path
        Output text file; refused if it exists unless ``overwrite`` (WHENet
        itself appends to an existing file; hpe never does).

    Notes
    -----
    Each line is ``image,yaw,pitch,roll`` -- yaw first, as in WHENet -- with
    degrees printed by Python's ``str(float)`` (shortest round-trip form).
    """
    atomic = AtomicFile(path, overwrite)
    lines = whenet_lines(frame, path)
    with atomic as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.writelines(lines)
    return Path(path)


def read_whenet(path):
    """Read an ``annotation.txt`` back as a table with ``image, pitch, yaw, roll`` (degrees)."""
    import pandas as pd

    path = Path(path)
    images, angles = [], []
    with open(path, encoding="utf-8") as fh:
        for n, line in enumerate(fh):
            line = line.rstrip("\r\n")
            if not line:
                continue
            parts = line.rsplit(",", 3)
            try:
                if len(parts) != 4:
                    raise ValueError
                yaw, pitch, roll = (float(x) for x in parts[1:])
            except ValueError:
                raise HpeError(f"{path}: line {n + 1}: expected 'image,yaw,pitch,roll', got {line[:80]!r}") from None
            images.append(parts[0])
            angles.append((pitch, yaw, roll))
    a = np.asarray(angles, dtype=np.float64).reshape(-1, 3)
    return pd.DataFrame({"image": images, "pitch": a[:, 0], "yaw": a[:, 1], "roll": a[:, 2]})
