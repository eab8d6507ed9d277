"""What every export layout shares: crop names, label rules, the hooks the export job calls."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def safe_name(s: str) -> str:
    """A file-name-safe version of ``s`` (runs of other characters become ``-``)."""
    return _SAFE.sub("-", str(s)).strip("-") or "x"


def crop_names(rows) -> np.ndarray:
    """Crop file names (no extension) that carry where each head came from.

    Panoptic-style rows (with ``camera``): ``<sequence>/<camera>_<person>_<frame:08d>`` -- the
    fields of WHENet's own crop names (``prepare_images.py``), plus the sequence folder. Other rows:
    ``<image stem>`` (``_<k>`` appended for the k-th head of an image with several). With several
    inputs, the ``source`` name is a leading folder.
    """
    n = len(rows)
    out = np.empty(n, dtype=object)
    multi_source = rows["source"].nunique() > 1
    cam = rows["camera"].to_numpy(dtype=object)
    seq = rows["sequence"].to_numpy(dtype=object)
    frame = rows["frame"].to_numpy()
    person = rows["person_id"].to_numpy()
    image = rows["image"].to_numpy(dtype=object)
    source = rows["source"].to_numpy(dtype=object)
    k_in_image = rows.groupby(["source", "image"], sort=False).cumcount().to_numpy()
    n_in_image = rows.groupby(["source", "image"], sort=False)["image"].transform("size").to_numpy()
    for i in range(n):
        if cam[i]:
            name = f"{safe_name(cam[i])}_{int(person[i])}_{int(frame[i]):08d}"
            if seq[i]:
                name = f"{safe_name(seq[i])}/{name}"
        else:
            stem = safe_name(Path(str(image[i])).with_suffix("").as_posix().replace("/", "__"))
            name = stem if n_in_image[i] == 1 else f"{stem}_{int(k_in_image[i])}"
        out[i] = f"{safe_name(source[i])}/{name}" if multi_source else name
    # the same head listed twice (or names equal after cleaning): later ones get _dup1, _dup2, ...
    import pandas as pd

    dup = pd.Series(out).groupby(out).cumcount().to_numpy()
    for i in np.flatnonzero(dup):
        out[i] = f"{out[i]}_dup{dup[i]}"
    return out


def abs_over(angles, limit, inclusive: bool = False) -> np.ndarray:
    """Rows where any of ``angles`` (N, k) has ``|a| > limit`` (``>=`` with ``inclusive``)."""
    a = np.abs(np.asarray(angles, dtype=np.float64))
    return (a >= limit).any(1) if inclusive else (a > limit).any(1)


class Layout:
    """Base of the layouts. Subclasses set the class attributes and override the hooks.

    Attributes
    ----------
    name : str
    system : str or None
        The rotation system the trainer reads (fixed), or None when ``--system`` chooses.
    full_frames : bool
        Whole images, one file per image (DirectMHP), instead of one crop per head.
    pixels : {"file", "jpeg", "array"}
        ``file``: workers write each JPEG at :meth:`relpath` under the split folder; ``jpeg``: workers
        return the encoded bytes and the layout stores them (:meth:`add_pixels`); ``array``: workers
        return the raw crop (uint8, H x W x 3, BGR).
    default_size : int or None
        Crop side the trainer expects (``--size`` overrides).
    uses_landmarks : bool
        The layout writes the 2-D landmarks (others never load them: less memory per row).
    stretch : bool
        Resize every crop to ``size x size`` even when the box is not square (the trainer's own script does).
    """

    name = ""
    system = None
    full_frames = False
    pixels = "file"
    default_size = None
    default_square = False
    stretch = False
    needs_landmarks = False
    uses_landmarks = False
    #: the trainer code that reads the layout, ``repo@commit file:lines`` (written to ``export.json``)
    loader = ""
    #: the trainer whose range rule applies (layouts read by several trainers: ``--trainer``)
    trainer = None
    #: ``--form`` values the layout accepts (empty: the option does not apply)
    forms: tuple = ()
    #: ``--trainer`` values the layout accepts (empty: the option does not apply)
    trainers: tuple = ()
    #: ``export.json`` ``split`` when neither ``--split`` nor ``--split-file`` is given
    default_split_note = "none (one split: train)"
    #: the layout writes a dataset card (:meth:`write_card`) after its index files
    writes_card = False

    def __init__(self, system=None, form=None, trainer=None, **options):
        if trainer is not None:
            raise ValueError(
                f"--trainer applies to --layout 6drepnet only (its file lists are read by Hopenet, "
                f"6DRepNet and 6DRepNet360), not to --layout {self.name}"
            )
        self.user_system = system
        self.form = form
        self.options = options
        self.root: Path | None = None

    # ---------------------------------------------------------------- rules
    def default_splits(self, rows) -> np.ndarray | None:
        """The split of each row when neither ``--split`` nor ``--split-file`` is given (None: all ``train``)."""
        return None

    def check_splits(self, splits) -> None:
        """Raise ``ValueError`` (with what to do) when the trainer needs splits the export does not have."""

    def label_reasons(self, angles: np.ndarray) -> np.ndarray:
        """Reasons (``''`` = keep) from the labels in the layout's system, ``(N, 3)`` pitch, yaw, roll degrees."""
        return np.full(len(angles), "", dtype=object)

    def crop_boxes(self, rows, boxes: np.ndarray, landmarks) -> np.ndarray:
        """Crop boxes ``x, y, w, h`` (before rounding); the default is the job's enlarged box."""
        return boxes

    # ---------------------------------------------------------------- output
    def relpath(self, rows, split: str) -> np.ndarray:
        """File name of each row's image, relative to the split folder."""
        return np.array([f"{n}.jpg" for n in crop_names(rows)], dtype=object)

    def split_dir(self, split: str) -> Path:
        return self.root / split

    def open(self, root: Path, splits) -> None:
        self.root = Path(root)

    def add_pixels(self, split: str, rows, payloads) -> None:  # pragma: no cover - only pixel layouts
        raise NotImplementedError

    def finish(self, exported, final_root: Path) -> list:
        """Write the index files for the exported rows (all splits); returns summary lines."""
        return []

    def write_card(self, exported, system, sampling: list, sources: dict, final_root: Path) -> None:
        """A description of the export next to its files (layouts with ``writes_card``); ``sources`` maps each
        source kind to its licence."""

    def abort(self) -> None:
        """Release open files after a failure (the staging folder is removed by the job)."""
