"""Export stage 1, load inputs: every input (label tables, 300W-LP/AFLW2000 ``.mat`` folders, the 300W-LP root)
as one label table with the image reference, head box, canonical matrix ``A`` (columns ``a00..a22``),
landmarks, group columns and a ``reason`` column (``''`` = usable)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa

from ...datasets.mat import read_mat_dir
from ...datasets.w300lp import read_w300lp
from ...errors import HpeError
from ...geometry.crop import landmark_boxes, sixdrepnet_test_boxes
from ...io import label_columns_fast, label_mode, open_table
from ...io.dataset_readers import find_reader
from ...io.label_source import label_source
from ...io.layout import BBOX_COLS, landmark_count
from ...registry import Registry
from ...rotation.systems import canonical_system
from .options import A_COLS


def _kind_of_table(schema) -> str:
    meta = schema.metadata or {}
    rel = meta.get(b"hpe:relabel")
    if rel:
        try:
            src = json.loads(rel).get("source", "")
        except ValueError:
            src = ""
        if "panoptic" in src:
            return "cmu_panoptic"
        if "agora" in src:
            return "agora"
    return "table"


def _subject_of(stem: str) -> str:
    """300W-LP identity ``NAME`` of ``NAME_k`` (the k-th synthesized view); other names unchanged."""
    return re.sub(r"_\d+$", "", stem) if re.search(r"_\d+_\d+$", stem) else stem


#: dataset reader name (:data:`hpe_cli.io.dataset_readers.READERS`) -> ``load(path, source, landmarks)``: the
#: export's own loading of that dataset (boxes from its landmarks...), a frame as :func:`load_table_input`'s, or
#: None to read the input as a label table after all. Inputs of other readers are read as label tables.
EXPORT_LOADERS = Registry("export input")


@EXPORT_LOADERS.register("mat")
def load_mat_input(path: Path, source: str, landmarks: bool = True):
    """A 300W-LP/AFLW2000 ``.mat`` folder: box from the visible ``pt2d`` points (else ``pt3d_68``).

    The box is 6DRepNet's loose AFLW2000 test crop of the tight landmark box (``k = 0.2``:
    :func:`hpe_cli.geometry.crop.sixdrepnet_test_boxes`), the margin its loader uses to show the whole head.
    """

    t = read_mat_dir(path, landmarks=True)
    n = len(t)
    n_lm = landmark_count(t.columns)
    if n_lm:
        lm = np.stack([t[[f"lm{i}_{a}" for i in range(n_lm)]].to_numpy(np.float64) for a in "xy"], -1)
    else:
        lm = np.full((n, 0, 2), np.nan)
    if "lm3d0_x" in t.columns:
        l3 = np.stack([t[[f"lm3d{i}_{a}" for i in range(68)]].to_numpy(np.float64) for a in "xy"], -1)
        if not n_lm:
            lm = l3
        fallback = ~np.isfinite(lm).all(-1).any(1)
        tight = np.where(fallback[:, None], landmark_boxes(l3), landmark_boxes(lm))
    else:
        tight = landmark_boxes(lm)
    box = sixdrepnet_test_boxes(tight)
    files = t["file"].astype(str).to_numpy()
    stems = [Path(f).with_suffix("").as_posix() for f in files]
    return _pose_para_frame(
        t,
        box,
        lm,
        landmarks,
        {
            "source": source,
            "kind": "300w_lp",
            "input": str(path),
            "row": files,
            "image": [s + ".jpg" for s in stems],
            "root": str(path if path.is_dir() else path.parent),
            "sequence": "",
            "camera": "",
            "frame": -1,
            "person_id": -1,
            "subject": [_subject_of(Path(s).name) for s in stems],
            "image_width": np.nan,
            "image_height": np.nan,
        },
    )


@EXPORT_LOADERS.register("300w-lp")
def load_w300lp_input(path: Path, source: str, landmarks: bool = True):
    """The 300W-LP root folder (``{AFW,HELEN,IBUG,LFPW}[_Flip]/NAME_k``, :func:`hpe_cli.datasets.w300lp.read_w300lp`).

    The box is built as for a ``.mat`` folder, from the copy's own ``landmarks/<subset>/NAME_k_pts.mat`` points
    when present (the main file's ``pt2d`` comes from the original image, 3DDFA issue #192), else ``pt2d``.
    The group column ``subject`` is the identity ``NAME``. None for ``300W-LP.zip`` (read as a label table).
    """
    if not path.is_dir():
        return None

    t = read_w300lp(path, landmarks=True, pt2d=True)
    n = len(t)

    def pts(prefix):
        L = 0
        while f"{prefix}{L}_x" in t.columns:
            L += 1
        if not L:
            return np.full((n, 0, 2), np.nan)
        return np.stack([t[[f"{prefix}{i}_{a}" for i in range(L)]].to_numpy(np.float64) for a in "xy"], -1)

    own, main = pts("lm"), pts("pt2d")
    main = np.where((main == -1).any(-1, keepdims=True), np.nan, main)
    has_own = np.isfinite(own).all(-1).any(1) if own.shape[1] else np.zeros(n, bool)
    lm = own if own.shape[1] else main
    if own.shape[1] and main.shape[1] and not has_own.all():
        L = max(own.shape[1], main.shape[1])
        pad = lambda a: np.concatenate([a, np.full((n, L - a.shape[1], 2), np.nan)], 1)
        lm = np.where(has_own[:, None, None], pad(own), pad(main))
    box = sixdrepnet_test_boxes(landmark_boxes(lm))
    return _pose_para_frame(
        t,
        box,
        lm,
        landmarks,
        {
            "source": source,
            "kind": "300w_lp",
            "input": str(path),
            "row": t["file"].astype(str).to_numpy(),
            "image": t["image"].astype(str).to_numpy(),
            "root": str(path),
            "sequence": "",
            "camera": "",
            "frame": -1,
            "person_id": -1,
            "subject": t["identity"].astype(str).to_numpy(),
            "image_width": np.nan,
            "image_height": np.nan,
        },
    )


def _pose_para_frame(t, box, lm, landmarks: bool, columns: dict):
    """Export rows of 300W-LP-style labels (``Pose_Para`` angles in ``300w_lp``): ``columns``, then the reason,
    box, canonical matrix, ``tdx..scale`` and (with ``landmarks``) the 2-D landmarks ``lm`` (n, L, 2)."""
    import pandas as pd

    n = len(t)
    pyr = t[["pitch", "yaw", "roll"]].to_numpy(np.float64)
    reasons = np.full(n, "", dtype=object)
    bad = ~np.isfinite(pyr).all(1)
    reasons[bad] = "non-finite Pose_Para angle"
    reasons[(reasons == "") & ~np.isfinite(box).all(1)] = "no visible 2-D landmark to box the head"
    sysm = canonical_system()
    A = sysm.to_canonical(sysm.from_angles(np.where(bad[:, None], 0.0, pyr))).reshape(n, 9)
    frame = pd.DataFrame({**columns, "reason": reasons})
    for k, c in enumerate(BBOX_COLS):
        frame[c] = box[:, k]
    for k, c in enumerate(A_COLS):
        frame[c] = A[:, k]
    for c in ("tdx", "tdy", "tdz", "scale"):
        frame[c] = t[c].to_numpy(np.float64)
    for i in range(lm.shape[1] if landmarks else 0):
        frame[f"lm{i}_x"], frame[f"lm{i}_y"] = lm[:, i, 0], lm[:, i, 1]
    return frame.copy()


#: columns of a label table the export keeps besides the box and the landmarks (when present)
TABLE_COLUMNS = (
    "image",
    "sequence",
    "camera",
    "frame",
    "person_id",
    "person",
    "subject",
    "image_width",
    "image_height",
)


def _check_crop_columns(path: Path, cols) -> None:
    missing = [c for c in ["image"] + BBOX_COLS if c not in cols]
    if missing:
        raise HpeError(
            f"{path}: expected columns {', '.join(missing)} (an image reference and a head box) "
            f"to export crops, got {', '.join(cols[:12])}{'...' if len(cols) > 12 else ''}"
        )


def _table_kind(src) -> str:
    """``cmu_panoptic``, ``agora`` (relabel outputs, by their metadata or relabel-agora's per-row ``source``) or
    ``table``: the licence of the exported rows."""
    kind = _kind_of_table(src.schema)
    if kind == "table" and "source" in src.columns:  # relabel-agora writes its source per row
        first = next(iter(src.batches_with_rejects()), (None, None))[0]
        if first is not None and first.num_rows and "agora" in str(first.column("source")[0]).lower():
            kind = "agora"
    return kind


def _batch_frame(batch, keep: list, labels, radians: bool):
    """One batch as the export's rows: kept columns, ``row``, canonical ``a00..a22``, ``reason``."""
    import pandas as pd

    nb = batch.num_rows
    lab, ok, reasons = label_columns_fast(batch, labels.mode, radians)
    reasons = np.full(nb, "", dtype=object) if reasons is None else reasons
    vals = np.stack(lab, -1)
    vals = np.where(ok[:, None], vals, 0.0)
    if labels.mode == "angles":
        R = labels.system.from_angles(vals)
    else:
        R = vals.reshape(-1, 3, 3)
        R = np.where(ok[:, None, None], R, np.eye(3))
    A = labels.system.to_canonical(R).reshape(nb, 9)
    df = pa.Table.from_batches([batch.select(keep)]).to_pandas()
    df.insert(0, "row", batch.column("__line__").to_numpy())
    box = df[BBOX_COLS].apply(pd.to_numeric, errors="coerce").to_numpy(np.float64)
    badbox = ~np.isfinite(box).all(1) | (box[:, 2] <= 0) | (box[:, 3] <= 0)
    reasons[(reasons == "") & badbox] = "missing or empty head box"
    df["reason"] = reasons
    for k, c in enumerate(A_COLS):
        df[c] = A[:, k]
    return df


def _unreadable_frame(unreadable: list):
    """Rows the reader could not parse, as rejected export rows (identity rotation, no box)."""
    import pandas as pd

    eye = np.eye(3).reshape(9)
    return pd.DataFrame(
        {
            "row": [ln for ln, _ in unreadable],
            "image": "",
            **{c: np.nan for c in BBOX_COLS},
            "reason": [r for _, r in unreadable],
            **{c: eye[k] for k, c in enumerate(A_COLS)},
        }
    )


def _group_columns(frame, path: Path, source: str, kind: str, images_root):
    """Every column the later stages read, with its default where the table has none."""
    import pandas as pd

    if "person_id" not in frame.columns and "person" in frame.columns:
        frame["person_id"] = frame.pop("person")
    frame["source"], frame["kind"], frame["input"] = source, kind, str(path)
    frame["root"] = str(images_root) if images_root else str(path.parent)
    for c, default in (
        ("sequence", ""),
        ("camera", ""),
        ("frame", -1),
        ("person_id", -1),
        ("image_width", np.nan),
        ("image_height", np.nan),
    ):
        if c not in frame.columns:
            frame[c] = default
    frame["sequence"] = frame["sequence"].fillna("").astype(str)
    frame["camera"] = frame["camera"].fillna("").astype(str)
    frame["image"] = frame["image"].fillna("").astype(str)
    frame["frame"] = pd.to_numeric(frame["frame"], errors="coerce").fillna(-1).astype(np.int64)
    frame["person_id"] = pd.to_numeric(frame["person_id"], errors="coerce").fillna(-1).astype(np.int64)
    if "subject" not in frame.columns:
        frame["subject"] = np.where(
            frame["person_id"].to_numpy() >= 0,
            frame["sequence"] + ":" + frame["person_id"].astype(str),
            [_subject_of(Path(s).stem) for s in frame["image"].tolist()],
        )
    frame["subject"] = frame["subject"].astype(str)
    return frame


def load_table_input(
    path: Path, source: str, input_system=None, images_root=None, landmarks: bool = True, radians: bool = False
):
    """A label table (relabel-panoptic/agora output or any table with image, box and labels); ``radians``: its
    angle columns are in radians (``--radians``; matrix columns and ``.mat`` folders are unaffected).

    The labels are opened once (:func:`hpe_cli.io.label_source.label_source`): the table's own system
    (``hpe:system`` metadata...), else ``--from``, else ``300w_lp``; angle or ``r00..r22`` columns.
    """
    import pandas as pd

    src = open_table(path, with_lines=True)
    cols = src.columns
    _check_crop_columns(path, cols)
    mode = label_mode(cols, path)  # angles or r00..r22: the export reads no system's own value columns
    labels = label_source(src, input_system, default="300w_lp", option_name="--from", mode=mode)
    kind = _table_kind(src)
    n_lm = landmark_count(cols) if landmarks else 0
    keep = [c for c in list(TABLE_COLUMNS) + BBOX_COLS if c in cols]
    keep += [f"lm{i}_{a}" for i in range(n_lm) for a in "xy"]
    parts = []
    unreadable = []
    for batch, bad in src.batches_with_rejects():
        unreadable += [(r.line, f"unreadable row: {r.reason}") for r in bad]
        if batch.num_rows:
            parts.append(_batch_frame(batch, keep, labels, radians))
    if unreadable:
        parts.append(_unreadable_frame(unreadable))
    if not parts:
        raise HpeError(f"{path}: no rows")
    frame = pd.concat(parts, ignore_index=True).sort_values("row", kind="stable", ignore_index=True)
    n = len(frame)
    frame = _group_columns(frame, path, source, kind, images_root)
    assert len(frame) == n
    return frame


def load_inputs(paths, images=(), input_system=None, landmarks: bool = True, radians: bool = False):
    """Every input as one table (a ``source`` column tells them apart); ``landmarks``: keep the 2-D points;
    ``radians``: the tables' angle columns are in radians."""
    import pandas as pd

    if images and len(images) not in (1, len(paths)):
        raise HpeError(f"expected one --images ROOT, or one per input ({len(paths)}), got {len(images)}")
    frames, names = [], set()
    for k, p in enumerate(paths):
        p = Path(p)
        if not p.exists():
            raise HpeError(f"{p}: no such file or folder")
        root = images[k] if len(images) == len(paths) else (images[0] if images else None)
        name = re.sub(r"\.(parquet|pq|csv)$", "", p.name) or "input"
        while name in names:
            name += "_"
        names.add(name)
        reader = find_reader(p)
        load = EXPORT_LOADERS.get(reader.name, None) if reader is not None else None
        f = load(p, name, landmarks) if load is not None else None
        if f is not None:
            if root:
                f["root"] = str(root)
        elif p.is_dir():
            raise HpeError(
                f"{p}: expected a label table (.parquet/.csv) or a folder of 300W-LP/AFLW2000 .mat "
                "files (BIWI: export its table with image and box columns)"
            )
        else:
            f = load_table_input(p, name, input_system, root, landmarks, radians)
        frames.append(f)
    frame = pd.concat(frames, ignore_index=True).copy()
    for c in [c for c in frame.columns if re.fullmatch(r"lm\d+_[xy]", c)]:
        frame[c] = frame[c].astype(np.float64)
    return frame
