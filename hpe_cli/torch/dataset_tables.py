"""Reading the label tables :class:`~hpe_cli.torch.dataset.HeadPoseDataset` takes: Parquet/CSV, list files, image references."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .. import read_labels
from ..datasets.mat import read_mat, read_mat_dir
from ..errors import HpeError
from ..geometry.augment import box_of_points
from ..io.layout import ANGLE_COLS, BBOX_COLS, MATRIX_COLS
from ..io.system_meta import system_from_metadata
from ..rotation.check import rotation_mask
from ..rotation.systems import get_system

#: columns naming the image of a row, in order of preference
IMAGE_COLUMNS = ("image", "image_path", "img_path", "file", "path", "filename")


IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".webp")


def join_paths(root, refs) -> list:
    """Image paths of refs with an image suffix (None: a ``.mat`` or bare name, resolved when read)."""
    base = str(root)
    out = []
    for ref in refs:
        ext = os.path.splitext(ref)[1].lower()
        out.append(os.path.join(base, ref) if ext in IMAGE_SUFFIXES else None)
    return out


# ------------------------------------------------------------------------------------ table loading
def load_table(labels, landmarks):
    """``(DataFrame, system or None, source name, parquet image info or None)``."""
    import pandas as pd

    if isinstance(labels, pd.DataFrame):
        return labels.reset_index(drop=True), None, "<DataFrame>", None
    path = Path(labels)
    if not path.exists():
        raise HpeError(f"{path}: no such file or folder")
    if path.is_file() and path.suffix.lower() == ".txt":
        return _read_list_file(path) + (None,)
    if (
        path.is_dir()
        and not any(path.glob("*.mat"))
        and (path / "data").is_dir()
        and any((path / "data").glob("*.parquet"))
    ):
        return _read_parquet(sorted((path / "data").glob("*.parquet")), path)
    if (path.is_dir() and any(path.glob("*.mat"))) or path.suffix.lower() == ".mat":
        table = read_mat_dir(path, landmarks=True)
        return table, get_system("300w_lp"), str(path), None
    if path.suffix.lower() in (".parquet", ".pq"):
        return _read_parquet([path], path)

    table, found = read_labels(path)
    return table, found, str(path), None


def _read_parquet(files, source):
    """Parquet shard(s) with labels; an image column of encoded bytes is read lazily per row."""

    import pandas as pd

    tables, offsets, groups, found, col, binary = [], [0], [], None, None, False
    for f, path in enumerate(files):
        pf = pq.ParquetFile(path)
        schema = pf.schema_arrow
        col = next((c for c in IMAGE_COLUMNS if c in schema.names), None)
        binary = col is not None and _is_image_bytes(schema.field(col).type)
        names = [c for c in schema.names if not (binary and c == col)]
        part = pf.read(columns=names).to_pandas()
        if binary:
            part[col] = ""  # placeholder: bytes are read lazily
        tables.append(part)
        for g in range(pf.metadata.num_row_groups):
            groups.append((f, g))
            offsets.append(offsets[-1] + pf.metadata.row_group(g).num_rows)
        found = found or system_from_metadata(schema.metadata, path)  # the one rule hpe's commands use
    table = pd.concat(tables, ignore_index=True)
    if "landmarks_x" in table.columns and "landmarks_y" in table.columns and "lm0_x" not in table.columns:
        lens = table["landmarks_x"].map(len)
        if len(table) and (lens == lens.iloc[0]).all():  # hf export: one list column per coordinate
            xs = np.stack(table["landmarks_x"].map(np.asarray).to_list())
            ys = np.stack(table["landmarks_y"].map(np.asarray).to_list())
            extra = {f"lm{k}_{a}": v[:, k] for k in range(xs.shape[1]) for a, v in (("x", xs), ("y", ys))}
            table = pd.concat([table, pd.DataFrame(extra)], axis=1)
    card = Path(source) / "README.md" if Path(source).is_dir() else None
    if found is None and card is not None and card.exists():  # hpe export --layout hf names it in the card
        m = re.search(r"in the rotation system `([^`]+)`", card.read_text(encoding="utf-8"))
        if m:
            found = get_system(m.group(1))
    parquet = ([str(f) for f in files], col, np.asarray(offsets), groups) if binary else None
    return table, found, str(source), parquet


def _read_list_file(path):
    """6DRepNet file lists (``hpe export --layout 6drepnet``), followed from thohemp/6DRepNet ``sixdrepnet/datasets.py``.

    - ``<split>/files.txt`` (``--form mat``): one name per line, no extension; ``<name>.mat`` holds
      ``Pose_Para`` (radians, the ``300w_lp`` system) and ``pt2d`` (visible points only), ``<name>.jpg`` the image.
    - ``files_<split>.txt`` (``--form crops``, DirectMHP's ``gen_dataset_full_AGORA_CMU.py``): ``<name>.jpg pitch
      yaw roll`` per line, degrees in the ``whenet`` system, images in the folder ``<split>/`` next to the list.
    """
    import pandas as pd

    path = path.resolve()
    lines = [ln.split() for ln in path.read_text(encoding="utf-8").splitlines()]
    rows = [(n + 1, ln) for n, ln in enumerate(lines) if ln]
    if not rows:
        raise HpeError(f"{path}: empty file list")
    widths = {len(ln) for _, ln in rows}
    if widths == {4}:
        try:
            ang = np.array([[float(v) for v in ln[1:]] for _, ln in rows])
        except ValueError:
            n, ln = next((n, ln) for n, ln in rows if not _floats(ln[1:]))
            raise HpeError(f"{path}: row {n}: expected '<name>.jpg pitch yaw roll', got {' '.join(ln)!r}") from None
        split = path.stem[len("files_") :] if path.stem.startswith("files_") else ""
        base = path.parent / split if split and (path.parent / split).is_dir() else path.parent
        table = pd.DataFrame(
            {"file": [str(base / ln[0]) for _, ln in rows], "pitch": ang[:, 0], "yaw": ang[:, 1], "roll": ang[:, 2]}
        )
        return table, get_system("whenet"), str(path)
    if widths != {1}:
        n, ln = next((n, ln) for n, ln in rows if len(ln) != len(rows[0][1]))
        raise HpeError(
            f"{path}: row {n}: expected one name per line (mat form) or '<name>.jpg pitch yaw roll' "
            f"(crops form), got {' '.join(ln)!r}"
        )
    recs, names = [], []
    for n, ln in rows:
        mat = path.parent / (ln[0] + ".mat")
        if not mat.exists():
            raise HpeError(f"{path}: row {n}: {mat} does not exist")
        recs.append(read_mat(mat))
        names.append(str(path.parent / ln[0]))
    table = pd.DataFrame(np.stack([r["pose"][:3] for r in recs]), columns=["pitch", "yaw", "roll"])
    table.insert(0, "file", names)

    boxes = np.full((len(recs), 4), np.nan)
    for k, r in enumerate(recs):  # visible points only, so their number varies: a box per file
        if r["pt2d"] is not None and r["pt2d"].size:
            boxes[k] = box_of_points(r["pt2d"].T)[0]
    table[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]] = boxes
    return table, get_system("300w_lp"), str(path)


def _floats(tokens) -> bool:
    try:
        [float(t) for t in tokens]
        return True
    except ValueError:
        return False


def _is_image_bytes(t) -> bool:

    if pa.types.is_binary(t) or pa.types.is_large_binary(t):
        return True
    return pa.types.is_struct(t) and any(t.field(k).name == "bytes" for k in range(t.num_fields))


def canonical_matrices(table, system, source) -> np.ndarray:
    """The table's labels (angles or matrix columns, in ``system``) as canonical rotation matrices, checked."""

    cols = set(table.columns)
    if all(c in cols for c in ANGLE_COLS):
        values = table[ANGLE_COLS].to_numpy(dtype=np.float64, na_value=np.nan)
        R = None
    elif all(c in cols for c in MATRIX_COLS):
        values = table[MATRIX_COLS].to_numpy(dtype=np.float64, na_value=np.nan).reshape(-1, 3, 3)
        R = values
    else:
        raise HpeError(
            f"{source}: expected angle columns pitch, yaw, roll (degrees) or matrix columns r00..r22, "
            f"found {', '.join(map(str, list(table.columns)[:12]))}"
        )
    bad = ~np.isfinite(values.reshape(len(values), -1)).all(axis=1)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        line = f"row {row + 2}" if str(source).lower().endswith(".csv") else f"row {row + 1}"
        raise HpeError(f"{source}: {line}: label is missing or not finite ({int(bad.sum())} such rows)")
    if R is None:
        R = system.from_angles(values)
    else:
        ok = rotation_mask(R)
        if not ok.all():
            row = int(np.flatnonzero(~ok)[0])
            raise HpeError(f"{source}: row {row + 1}: r00..r22 is not a rotation matrix")
    return system.to_canonical(R)


def table_boxes(table):
    """The table's box columns as a float array, or None without them."""

    if not all(c in table.columns for c in BBOX_COLS):
        return None
    return table[BBOX_COLS].to_numpy(dtype=np.float64, na_value=np.nan)


def table_landmarks(table, prefix):
    """The table's ``<prefix><k>_x/_y`` landmark columns as an ``(N, K, 2)`` array, or None without them."""
    if prefix is None:
        return None
    n = 0
    while f"{prefix}{n}_x" in table.columns and f"{prefix}{n}_y" in table.columns:
        n += 1
    if n == 0:
        return None
    cols = [f"{prefix}{k}_{a}" for k in range(n) for a in "xy"]
    return table[cols].to_numpy(dtype=np.float64, na_value=np.nan).reshape(-1, n, 2)
