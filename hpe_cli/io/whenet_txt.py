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
from .coco import column_values, frame_column_names, frame_parts, string_column
from .writers import StreamWriter

#: column order of one line, as WHENet writes it
WHENET_FIELDS = ("image", "yaw", "pitch", "roll")


def whenet_lines(frame, path="<annotation.txt>", offset: int = 0) -> list:
    """The ``annotation.txt`` lines (with their newline) of a label table or batch.

    ``frame`` is a pandas DataFrame, pyarrow Table or RecordBatch; ``offset``
    is the index of its first row in the whole table (for error messages).
    """

    missing = [c for c in WHENET_FIELDS if c not in frame_column_names(frame)]
    if missing:
        raise HpeError(f"{path}: expected columns {', '.join(missing)} in the label table")
    images = string_column(frame, "image")
    for k, im in enumerate(images):
        if "," in im or "\n" in im or "\r" in im:
            raise HpeError(
                f"{path}: row {offset + k}: expected an image path without commas or line breaks, got {im!r}"
            )
    cols = []
    for c in WHENET_FIELDS[1:]:
        v = column_values(frame, c)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise HpeError(f"{path}: row {offset + bad[0]}: expected a finite {c}, got {v[bad[0]]}")
        cols.append(v.tolist())
    # str(float) is the shortest repr that round-trips, exactly what WHENet writes
    return [f"{im},{y!s},{p!s},{r!s}\n" for im, y, p, r in zip(images, *cols)]


def whenet_text(frame, path="<annotation.txt>", offset: int = 0) -> bytes:
    """The ``annotation.txt`` lines of a label batch as UTF-8 bytes (see :func:`whenet_lines`).

    Lines do not depend on how the table is cut into batches, so texts made
    apart (in worker processes) and concatenated are the bytes
    :class:`WhenetWriter` writes for the whole table.
    """
    return "".join(whenet_lines(frame, path, offset)).encode("utf-8")


class WhenetWriter(StreamWriter):
    """Write ``annotation.txt`` batch by batch, atomically (see :func:`write_whenet`); the bytes go to the file
    from a background thread (:class:`~hpe_cli.io.writers.StreamWriter`) while the next batch is formatted."""

    def write(self, frame) -> None:
        self.append_text(whenet_text(frame, self.path, self.rows), len(frame))


def write_whenet(frame, path, overwrite: bool = False, batch_size: int = 65536) -> Path:
    """Write a label table as WHENet ``annotation.txt`` lines, atomically.

    Parameters
    ----------
    frame : pandas.DataFrame, pyarrow Table, or an iterable of either
        Needs ``image`` (path, written as is) and ``pitch, yaw, roll``
        (degrees). Other columns, such as the box, are not part of the format
        and are ignored. An iterable of batches is written as it comes.
    path : str or Path
        Output text file; refused if it exists unless ``overwrite`` (WHENet
        itself appends to an existing file; hpe never does).

    Notes
    -----
    Each line is ``image,yaw,pitch,roll`` -- yaw first, as in WHENet -- with
    degrees printed by Python's ``str(float)`` (shortest round-trip form).
    """

    with WhenetWriter(path, overwrite) as w:
        for part in frame_parts(frame, batch_size):
            w.write(part)
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
