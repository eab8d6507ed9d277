"""The tables of ``hpe view``: LABELS (and OTHER) read whole, each in its own system, and OTHER's rows paired
with LABELS' by key as ``hpe evaluate`` pairs them (:func:`hpe_cli.pipelines.evaluate.join.join`: same key
choice, stems, duplicate checks; no common key is a usage error)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from ...io.label_source import LabelSource, open_labels
from ..draw.rows import read_rows, row_namer, row_numbers
from ..evaluate.join import choose_keys, join
from ..evaluate.sides import Side

#: key columns tried together with the image name when no --key is given (one image holds several heads)
PERSON_KEYS = ("person_id", "face_id", "head_id")


@dataclass
class Table:
    """One input table, read whole."""

    labels: LabelSource
    frame: object  # pandas DataFrame of every column
    A: np.ndarray  # (N, 3, 3) canonical; NaN where unusable
    angles: np.ndarray  # (N, 3) pitch, yaw, roll in ``system``
    reasons: np.ndarray  # (N,) object, "" when usable
    lines: np.ndarray | None
    pose_para: bool
    where: object  # row namer

    @property
    def src(self):
        """The :class:`~hpe_cli.io.table_source.TableSource`."""
        return self.labels.table

    @property
    def resolved(self):
        """The system the labels were read in and where it came from."""
        return self.labels.resolved

    @property
    def system(self):
        """The system the page shows this table's angles in."""
        return self.labels.output_system

    @property
    def n(self) -> int:
        return len(self.frame)

    def row_numbers(self):
        """Each row's number as messages and rejects files give it."""
        return row_numbers(self.src, self.lines, np.arange(self.n))


def read_table(path, system, use, radians, option_name="--system") -> Table:
    """Read ``path`` whole: its own system (file metadata, dataset format) else ``system``."""
    labels = open_labels(path, system, option_name=option_name, option_is_output=True, mode=use)
    frame, A, angles, reasons, lines = read_rows(labels, radians)
    p = Path(path)
    columns = set(labels.columns)
    pose_para = p.is_dir() or p.suffix.lower() == ".mat" or {"tdz", "scale"} <= columns
    pose_para = pose_para and not {"bbox_x", "bbox_y"} <= columns
    return Table(labels, frame, A, angles, reasons, lines, pose_para, row_namer(labels.table, lines))


def _key_table(t: Table, keys):
    """The key columns as an Arrow table; a dataset reader's ``file`` also gives ``image`` = its stem."""
    cols = {}
    for k in keys:
        if k in t.frame.columns:
            v = t.frame[k]
        elif k == "image" and "file" in t.frame.columns:
            v = t.frame["file"].astype(str).str.replace(r"^.*[\\/]|\.[^.\\/]*$", "", regex=True)
        else:
            continue
        cols[k] = pa.array(v.to_numpy(dtype=object), from_pandas=True)
    return pa.table(cols)


def default_keys(a: Table, b: Table, keys) -> list:
    """``--key`` as given, else evaluate's choice (image, file) plus a person id both tables have."""
    cols_a, cols_b = list(a.frame.columns), list(b.frame.columns)
    for t, cols in ((a, cols_a), (b, cols_b)):
        if "file" in cols and "image" not in cols and t.labels.dataset:
            cols.append("image")
    chosen = choose_keys(keys, cols_b, cols_a, b.src.path, a.src.path)
    if not keys:
        chosen += [k for k in PERSON_KEYS if k in cols_a and k in cols_b][:1]
    return chosen


def pair(a: Table, b: Table, keys) -> tuple:
    """``(b_idx per row of a (-1: none), unmatched rows of b, keys, notes)`` by :func:`hpe_cli.pipelines.evaluate.join.join`."""
    keys = default_keys(a, b, keys)

    def side(t: Table):
        s = Side(
            t.src.path, t.system, "", [np.zeros(0)] * 9, t.reasons == "", None, _key_table(t, keys), None,
            list(t.frame.columns), t.lines if t.lines is not None else np.arange(1, t.n + 1), [],
        )  # fmt: skip
        s.unit = "line" if t.src.unit == "line" else "row"
        return s

    _, bidx, unmatched, notes = join(side(b), side(a), keys)
    return bidx, unmatched, keys, notes
