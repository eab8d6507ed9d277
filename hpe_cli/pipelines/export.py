"""``hpe export``: training-ready datasets in the layout each trainer reads (crops, splits, sampling).

The job: read every input into one label table (image, box, canonical matrix ``A``, landmarks, groups),
express the labels in the layout's rotation system through the matrices (never by editing angles), apply the
layout's own rules, the split, ``--min-change`` and ``--balance``, then decode each source image once, crop
every head in it (padding outside the frame), encode, and let the layout write its index files. Everything goes
into a staging folder that replaces OUT_DIR only at the end; every input label that is not exported is a reject
with its reason.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import HpeError
from ..geometry.crop import expand_boxes, landmark_boxes, pixel_boxes, sixdrepnet_test_boxes
from ..io.export import get_layout
from ..io.layout import BBOX_COLS, landmark_count

A_COLS = [f"a{i}{j}" for i in range(3) for j in range(3)]
MATRIX_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]
META = ["source", "input", "row", "image", "sequence", "camera", "frame", "person_id", "subject"]
SPLIT_NAMES = {1: ["train"], 2: ["train", "val"], 3: ["train", "val", "test"]}
LICENCES = {
    "cmu_panoptic": "CMU Panoptic Studio (domedb.perception.cs.cmu.edu): non-commercial research use; cite Joo et "
                    "al. Labels relabelled by hpe from the 3-D face landmarks.",
    "agora": "AGORA (agora.is.tue.mpg.de): its licence allows non-commercial scientific research only.",
    "300w_lp": "300W-LP / AFLW2000-3D (3DDFA, Zhu et al.): research use only; images from 300W/AFLW keep their "
               "original terms.",
    "biwi": "BIWI Kinect Head Pose (ETH Zurich): research use only.",
    "table": "a label table: check the licence of the dataset it came from.",
}
NO_VIDEO = "no image (hdImgs missing; video source not available)"
NO_FILES = "no image (neither hdImgs/<cam>/<cam>_<frame>.jpg nor hdVideos/hd_<cam>.mp4 found)"


# ----------------------------------------------------------------------------------------------- options
@dataclass
class ExportOptions:
    layout: str
    images: tuple = ()
    system: object = None
    input_system: object = None
    form: str | None = None
    crop_scale: float | None = None
    square: bool | None = None
    size: int | None = None
    quality: int = 95
    pad_value: int = 0
    min_inside: float = 0.5
    split: str | None = None
    split_file: str | None = None
    min_change: float | None = None
    balance: str | None = None
    seed: int = 0
    drop_images_with_rejects: bool = False
    workers: int = 1
    overwrite: bool = False
    rejects: str | None = None
    strict: bool = False
    quiet: bool = True
    sampling_notes: list = field(default_factory=list)


# ----------------------------------------------------------------------------------------------- inputs
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


def _table_system(src, given):
    from ..io.system_meta import resolve_system

    return resolve_system(src, given, default="300w_lp", option_name="--from").system


def _subject_of(stem: str) -> str:
    """300W-LP identity ``NAME`` of ``NAME_k`` (the k-th synthesized view); other names unchanged."""
    return re.sub(r"_\d+$", "", stem) if re.search(r"_\d+_\d+$", stem) else stem


def load_mat_input(path: Path, source: str, landmarks: bool = True):
    """A 300W-LP/AFLW2000 ``.mat`` folder: box from the visible ``pt2d`` points (else ``pt3d_68``).

    The box is 6DRepNet's loose AFLW2000 test crop of the tight landmark box (``k = 0.2``:
    :func:`hpe_cli.geometry.crop.sixdrepnet_test_boxes`), the margin its loader uses to show the whole head.
    """
    from ..datasets.mat import read_mat_dir

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
    return _pose_para_frame(t, box, lm, landmarks, {
        "source": source, "kind": "300w_lp", "input": str(path), "row": files, "image": [s + ".jpg" for s in stems],
        "root": str(path if path.is_dir() else path.parent), "sequence": "", "camera": "", "frame": -1,
        "person_id": -1, "subject": [_subject_of(Path(s).name) for s in stems],
        "image_width": np.nan, "image_height": np.nan})


def load_w300lp_input(path: Path, source: str, landmarks: bool = True):
    """The 300W-LP root folder (``{AFW,HELEN,IBUG,LFPW}[_Flip]/NAME_k``, :func:`hpe_cli.datasets.w300lp.read_w300lp`).

    The box is built as for a ``.mat`` folder, from the copy's own ``landmarks/<subset>/NAME_k_pts.mat`` points
    when present (the main file's ``pt2d`` comes from the original image, 3DDFA issue #192), else ``pt2d``.
    The group column ``subject`` is the identity ``NAME``.
    """
    from ..datasets.w300lp import read_w300lp

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
        pad = lambda a: np.concatenate([a, np.full((n, L - a.shape[1], 2), np.nan)], 1)  # noqa: E731
        lm = np.where(has_own[:, None, None], pad(own), pad(main))
    box = sixdrepnet_test_boxes(landmark_boxes(lm))
    return _pose_para_frame(t, box, lm, landmarks, {
        "source": source, "kind": "300w_lp", "input": str(path), "row": t["file"].astype(str).to_numpy(),
        "image": t["image"].astype(str).to_numpy(), "root": str(path), "sequence": "", "camera": "", "frame": -1,
        "person_id": -1, "subject": t["identity"].astype(str).to_numpy(), "image_width": np.nan,
        "image_height": np.nan})


def _pose_para_frame(t, box, lm, landmarks: bool, columns: dict):
    """Export rows of 300W-LP-style labels (``Pose_Para`` angles in ``300w_lp``): ``columns``, then the reason,
    box, canonical matrix, ``tdx..scale`` and (with ``landmarks``) the 2-D landmarks ``lm`` (n, L, 2)."""
    import pandas as pd

    from ..rotation.systems import get_system

    n = len(t)
    pyr = t[["pitch", "yaw", "roll"]].to_numpy(np.float64)
    reasons = np.full(n, "", dtype=object)
    bad = ~np.isfinite(pyr).all(1)
    reasons[bad] = "non-finite Pose_Para angle"
    reasons[(reasons == "") & ~np.isfinite(box).all(1)] = "no visible 2-D landmark to box the head"
    sysm = get_system("300w_lp")
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


def load_table_input(path: Path, source: str, input_system=None, images_root=None, landmarks: bool = True):
    """A label table (relabel-panoptic/agora output or any table with image, box and labels)."""
    import pandas as pd
    import pyarrow as pa

    from ..io import label_columns_fast, label_mode, open_table

    src = open_table(path, with_lines=True)
    cols = src.columns
    missing = [c for c in ["image"] + BBOX_COLS if c not in cols]
    if missing:
        raise HpeError(f"{path}: expected columns {', '.join(missing)} (an image reference and a head box) "
                       f"to export crops, got {', '.join(cols[:12])}{'...' if len(cols) > 12 else ''}")
    mode = label_mode(cols, path)
    system = _table_system(src, input_system)
    kind = _kind_of_table(src.schema)
    n_lm = landmark_count(cols) if landmarks else 0
    keep = [c for c in ["image", "sequence", "camera", "frame", "person_id", "person", "subject", "image_width",
                        "image_height"] + BBOX_COLS if c in cols]
    if kind == "table" and "source" in cols:  # relabel-agora writes its source per row
        first = next(iter(src.batches_with_rejects()), (None, None))[0]
        if first is not None and first.num_rows and "agora" in str(first.column("source")[0]).lower():
            kind = "agora"
    keep += [f"lm{i}_{a}" for i in range(n_lm) for a in "xy"]
    parts = []
    unreadable = []
    for batch, bad in src.batches_with_rejects():
        unreadable += [(r.line, f"unreadable row: {r.reason}") for r in bad]
        nb = batch.num_rows
        if nb == 0:
            continue
        lab, ok, reasons = label_columns_fast(batch, mode)
        reasons = np.full(nb, "", dtype=object) if reasons is None else reasons
        vals = np.stack(lab, -1)
        vals = np.where(ok[:, None], vals, 0.0)
        if mode == "angles":
            R = system.from_angles(vals)
        else:
            R = vals.reshape(-1, 3, 3)
            R = np.where(ok[:, None, None], R, np.eye(3))
        A = system.to_canonical(R).reshape(nb, 9)
        df = pa.Table.from_batches([batch.select(keep)]).to_pandas()
        df.insert(0, "row", batch.column("__line__").to_numpy())
        box = df[BBOX_COLS].apply(pd.to_numeric, errors="coerce").to_numpy(np.float64)
        badbox = ~np.isfinite(box).all(1) | (box[:, 2] <= 0) | (box[:, 3] <= 0)
        reasons[(reasons == "") & badbox] = "missing or empty head box"
        df["reason"] = reasons
        for k, c in enumerate(A_COLS):
            df[c] = A[:, k]
        parts.append(df)
    if unreadable:
        eye = np.eye(3).reshape(9)
        parts.append(pd.DataFrame({"row": [ln for ln, _ in unreadable], "image": "",
                                   **{c: np.nan for c in BBOX_COLS}, "reason": [r for _, r in unreadable],
                                   **{c: eye[k] for k, c in enumerate(A_COLS)}}))
    if not parts:
        raise HpeError(f"{path}: no rows")
    frame = pd.concat(parts, ignore_index=True).sort_values("row", kind="stable", ignore_index=True)
    n = len(frame)
    if "person_id" not in frame.columns and "person" in frame.columns:
        frame["person_id"] = frame.pop("person")
    frame["source"], frame["kind"], frame["input"] = source, kind, str(path)
    frame["root"] = str(images_root) if images_root else str(path.parent)
    for c, default in (("sequence", ""), ("camera", ""), ("frame", -1), ("person_id", -1),
                       ("image_width", np.nan), ("image_height", np.nan)):
        if c not in frame.columns:
            frame[c] = default
    frame["sequence"] = frame["sequence"].fillna("").astype(str)
    frame["camera"] = frame["camera"].fillna("").astype(str)
    frame["image"] = frame["image"].fillna("").astype(str)
    frame["frame"] = pd.to_numeric(frame["frame"], errors="coerce").fillna(-1).astype(np.int64)
    frame["person_id"] = pd.to_numeric(frame["person_id"], errors="coerce").fillna(-1).astype(np.int64)
    if "subject" not in frame.columns:
        frame["subject"] = np.where(frame["person_id"].to_numpy() >= 0,
                                    frame["sequence"] + ":" + frame["person_id"].astype(str),
                                    [_subject_of(Path(s).stem) for s in frame["image"].tolist()])
    frame["subject"] = frame["subject"].astype(str)
    assert len(frame) == n
    return frame


def load_inputs(paths, images=(), input_system=None, landmarks: bool = True):
    """Every input as one table (a ``source`` column tells them apart); ``landmarks``: keep the 2-D points."""
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
        from ..datasets.w300lp import is_w300lp_root

        is_mat = (p.is_dir() and any(p.glob("*.mat"))) or p.suffix.lower() == ".mat"
        if p.is_dir() and not is_mat and is_w300lp_root(p):
            f = load_w300lp_input(p, name, landmarks)
            if root:
                f["root"] = str(root)
        elif is_mat:
            f = load_mat_input(p, name, landmarks)
            if root:
                f["root"] = str(root)
        elif p.is_dir():
            raise HpeError(f"{p}: expected a label table (.parquet/.csv) or a folder of 300W-LP/AFLW2000 .mat "
                           "files (BIWI: export its table with image and box columns)")
        else:
            f = load_table_input(p, name, input_system, root, landmarks)
        frames.append(f)
    frame = pd.concat(frames, ignore_index=True).copy()
    for c in [c for c in frame.columns if re.fullmatch(r"lm\d+_[xy]", c)]:
        frame[c] = frame[c].astype(np.float64)
    return frame


# ----------------------------------------------------------------------------------------------- sampling
def parse_split(spec: str):
    """``COL:0.8,0.2`` or ``COL:train=0.8,val=0.2`` -> (column, names, fractions)."""
    try:
        col, rest = spec.split(":", 1)
        items = [s.strip() for s in rest.split(",") if s.strip()]
        names, fr = [], []
        for k, it in enumerate(items):
            if "=" in it:
                n, v = it.split("=", 1)
            else:
                n, v = None, it
            names.append(n)
            fr.append(float(v))
        if not col or not fr or any(f < 0 for f in fr) or sum(fr) <= 0:
            raise ValueError
    except ValueError:
        raise HpeError(f"--split: expected COL:FRACTIONS such as sequence:0.8,0.2, got {spec!r}") from None
    if any(n is None for n in names):
        if len(fr) not in SPLIT_NAMES:
            raise HpeError(f"--split: name the splits (train=0.7,...) when there are more than 3, got {spec!r}")
        names = SPLIT_NAMES[len(fr)]
    check_split_names(names, "--split")
    fr = np.asarray(fr) / sum(fr)
    return ("subject" if col == "identity" else col), list(names), fr


def check_split_names(names, where: str) -> None:
    """Split names become folder and file names: letters, digits, ``_`` and ``-`` only, unique."""
    for n in names:
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_-]*", str(n)):
            raise HpeError(f"{where}: expected split names of letters, digits, '_' and '-', got {n!r}")
    if len(set(names)) != len(names):
        raise HpeError(f"{where}: expected distinct split names, got {', '.join(map(str, names))}")


def group_hash(values, seed: int) -> np.ndarray:
    """A deterministic 64-bit key per group value (sha256 of ``seed:value``)."""
    return np.array([int.from_bytes(hashlib.sha256(f"{seed}:{v}".encode()).digest()[:8], "big")
                     for v in values], dtype=np.uint64)


def assign_splits(groups, names, fractions, seed: int = 0) -> np.ndarray:
    """Split rows by group: groups in hash order fill the splits by row count; one group, one split.

    Groups are laid end to end in the order of their hash; a group goes to the split whose share of the rows
    holds the group's midpoint. Deterministic for a given ``seed`` and independent of row order.
    """
    groups = np.asarray(groups).astype(str)
    uniq, inv, counts = np.unique(groups, return_inverse=True, return_counts=True)
    order = np.argsort(group_hash(uniq.tolist(), seed), kind="stable")
    before = np.cumsum(counts[order]) - counts[order]  # rows in earlier groups
    edges = np.cumsum(fractions)[:-1] * groups.size
    which = np.searchsorted(edges, before + counts[order] / 2, side="right")
    split_of_group = np.empty(uniq.size, dtype=object)
    split_of_group[order] = np.asarray(names, dtype=object)[which]
    return split_of_group[inv.reshape(-1)]


def read_split_file(path):
    """``--split-file``: a CSV whose header names the group column, then ``split``; returns (col, mapping)."""
    import pandas as pd

    try:
        t = pd.read_csv(path, dtype=str, keep_default_na=False)
    except Exception as exc:
        raise HpeError(f"{path}: cannot read ({' '.join(str(exc).split())[:160]})") from None
    if t.shape[1] != 2 or "split" not in t.columns:
        raise HpeError(f"{path}: expected two columns, a group column (e.g. sequence) and split, "
                       f"got {', '.join(t.columns)}")
    col = [c for c in t.columns if c != "split"][0]
    dup = t[col].duplicated(keep=False) & (t.groupby(col)["split"].transform("nunique") > 1)
    if dup.any():
        k = int(np.flatnonzero(dup.to_numpy())[0])
        raise HpeError(f"{path}: line {k + 2}: group {t[col].iloc[k]!r} is in two splits")
    for n in sorted(set(t["split"].tolist())):
        check_split_names([n], str(path))
    return ("subject" if col == "identity" else col), dict(zip(t[col].tolist(), t["split"].tolist()))


def geodesic(A, B) -> float:
    c = (np.trace(A.T @ B) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def min_change_keep(keys, frames, A, deg: float, ok) -> np.ndarray:
    """Per group (``keys``), in frame order, keep a row only if its rotation differs from the last kept
    one of that group by more than ``deg`` (geodesic angle); the first row of a group is kept.

    Rows with ``ok`` False are skipped (neither kept nor compared). Returns a boolean keep mask.
    """
    n = len(frames)
    keep = np.zeros(n, dtype=bool)
    order = np.lexsort((np.arange(n), frames, keys))
    A = np.asarray(A).reshape(n, 3, 3)
    last = {}
    for i in order.tolist():
        if not ok[i]:
            continue
        k = keys[i]
        prev = last.get(k)
        if prev is None or geodesic(A[prev], A[i]) > deg:
            keep[i] = True
            last[k] = i
    return keep


def parse_balance(spec: str):
    m = re.fullmatch(r"yaw:([0-9.]+):(\d+)", spec or "")
    if not m or float(m.group(1)) <= 0:
        raise HpeError(f"--balance: expected yaw:BIN:MAX (bin width in degrees, max samples per bin), got {spec!r}")
    return float(m.group(1)), int(m.group(2))


def balance_keep(yaw, bin_deg: float, max_per_bin: int, ok, seed: int = 0):
    """At most ``max_per_bin`` usable rows per yaw bin ``[-180 + k*bin, ...)``, chosen with ``seed``.

    Returns (keep mask, bin index per row). Deterministic: bins in order, one generator.
    """
    yaw = np.asarray(yaw, dtype=np.float64)
    bins = np.floor((yaw + 180.0) / bin_deg).astype(np.int64)
    keep = ok.copy()
    rng = np.random.default_rng(seed)
    for b in np.unique(bins[ok]).tolist():
        idx = np.flatnonzero(ok & (bins == b))
        if idx.size > max_per_bin:
            chosen = np.sort(rng.permutation(idx.size)[:max_per_bin])
            drop = np.ones(idx.size, dtype=bool)
            drop[chosen] = False
            keep[idx[drop]] = False
    return keep, bins


# ----------------------------------------------------------------------------------------------- images
def resolve_image(root: str, image: str, sequence: str, camera: str, frame: int):
    """The image file for a row, or None: ``<root>/<image>``, ``<root>/<sequence>/<image>``, and for Panoptic
    rows :func:`hpe_cli.datasets.panoptic.hd_image_path` (``hdImgs/<cam>/<cam>_<frame:08d>.jpg`` or the
    ``hdImgs/hd_<cam>/<frame:08d>.jpg`` layout some copies use) under both."""
    r = Path(root)
    cands = [r / image]
    bases = (r, r / sequence) if sequence else (r,)
    if sequence:
        cands.append(r / sequence / image)
    if camera and frame >= 0:
        from ..datasets.panoptic import hd_image_path

        for base in bases:
            try:
                cands.append(hd_image_path(base, camera, frame))
            except HpeError:
                break
    for c in cands:
        if c.is_file():
            return str(c)
    return None


def video_path(root: str, sequence: str, camera: str):
    """``hdVideos/hd_<cam>.mp4`` under ``root`` or ``root/sequence`` (:func:`~hpe_cli.datasets.panoptic.hd_video_path`)."""
    from ..datasets.panoptic import hd_video_path

    bases = (Path(root), Path(root) / sequence) if sequence else (Path(root),)
    return next((str(v) for v in (hd_video_path(b, camera) for b in bases) if v.is_file()), None)


def jpeg_size(data: bytes):
    """(width, height) from a JPEG's SOF header, or None."""
    if data[:2] != b"\xff\xd8":
        return None
    i, n = 2, len(data)
    while i + 9 < n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        seg = int.from_bytes(data[i + 2:i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            h = int.from_bytes(data[i + 5:i + 7], "big")
            w = int.from_bytes(data[i + 7:i + 9], "big")
            return (w, h) if w > 0 and h > 0 else None
        i += 2 + seg
    return None


_CFG: dict = {}
_LAST_FRAME: list = [None]


def _init_worker(cfg):
    global _CFG
    _CFG = cfg
    import cv2

    cv2.setNumThreads(1)


def _encode(crop, cfg):
    import cv2

    ok, buf = cv2.imencode(".jpg", crop, [cv2.IMWRITE_JPEG_QUALITY, cfg["quality"]])
    if not ok:
        raise HpeError("cannot encode a JPEG crop")
    return buf


def _process_image(image, data, items, cfg, out):
    """Crop/encode every item of one decoded image (or copy the file for full frames)."""
    import cv2

    from ..geometry.crop import crop_padded

    H, W = image.shape[:2]
    wrote_full = False
    for it in items:
        idx, split, rel, box, bbox, osz = it
        bx, by, bw, bh = bbox  # fraction of the head box inside the frame (scalar form of inside_fraction)
        iw = max(0.0, min(bx + bw, W) - max(bx, 0.0))
        ih = max(0.0, min(by + bh, H) - max(by, 0.0))
        frac = iw * ih / (bw * bh) if bw * bh > 0 else 0.0
        if frac < cfg["min_inside"]:
            out.append((idx, f"box outside the image ({frac * 100:.0f}% inside)", W, H, None))
            continue
        if cfg["full_frames"]:
            if not wrote_full:
                dst = os.path.join(cfg["root"], cfg["split_dirs"][split], rel)
                os.makedirs(os.path.dirname(dst), exist_ok=True)
                if data is not None:
                    with open(dst, "wb") as fh:
                        fh.write(data)
                else:
                    _encode(image, cfg).tofile(dst)
                wrote_full = True
            out.append((idx, "", W, H, None))
            continue
        crop = crop_padded(image, box, cfg["pad_value"])
        if osz is not None and (crop.shape[1], crop.shape[0]) != tuple(osz):
            crop = cv2.resize(crop, tuple(osz), interpolation=cv2.INTER_AREA
                              if osz[0] < crop.shape[1] else cv2.INTER_LINEAR)
        if cfg["pixels"] == "array":
            out.append((idx, "", W, H, _spill(np.ascontiguousarray(crop), cfg)))
            continue
        buf = _encode(crop, cfg)
        if cfg["pixels"] == "jpeg":
            out.append((idx, "", W, H, _spill(buf.tobytes(), cfg)))
        else:
            dst = os.path.join(cfg["root"], cfg["split_dirs"][split], rel)
            d = os.path.dirname(dst)
            if d not in cfg["made"]:
                os.makedirs(d, exist_ok=True)
                cfg["made"].add(d)
            buf.tofile(dst)
            out.append((idx, "", W, H, None))


def _spill(payload, cfg):
    """In a video task, pixels go to the task's spill file (a video can hold thousands of heads): the parent
    reads them back one by one, so neither process holds a whole video's crops."""
    fh = cfg.get("spill")
    if fh is None:
        return payload
    if isinstance(payload, np.ndarray):
        data, shape = payload.tobytes(), payload.shape
    else:
        data, shape = payload, None
    off = fh.tell()
    fh.write(data)
    return ("spill", off, len(data), shape)


def _unspill(payload, fh):
    if isinstance(payload, tuple) and payload and payload[0] == "spill":
        _, off, n, shape = payload
        fh.seek(off)
        data = fh.read(n)
        return np.frombuffer(data, np.uint8).reshape(shape) if shape is not None else data
    return payload


def _work(task):
    """Run one task; returns ``(results, spill file or None)``."""
    cfg = _CFG
    if task[0] != "video" or cfg["pixels"] == "file":
        return _work_items(task), None
    fd, spill = tempfile.mkstemp(prefix=".spill-", suffix=".bin", dir=cfg["root"])
    with os.fdopen(fd, "wb") as fh:
        cfg["spill"] = fh
        try:
            out = _work_items(task)
        finally:
            cfg["spill"] = None
    return out, spill


def _work_items(task):
    """One task: an image file (or a video with its frames) and the heads to crop from it."""
    import cv2

    cfg = _CFG
    kind, src, groups = task
    out = []
    if kind == "video":
        try:
            from ..datasets.panoptic_video import VideoFrames
        except ImportError:
            return [(it[0], NO_VIDEO, -1, -1, None) for items in groups.values() for it in items]
        if src is None:
            return [(it[0], NO_FILES, -1, -1, None) for items in groups.values() for it in items]
        try:
            for fr, img, reason in VideoFrames(src).read(sorted(groups)):
                items = groups.get(fr, [])
                if img is None:
                    out += [(it[0], f"no image (video {src} frame {fr}: {reason})", -1, -1, None) for it in items]
                else:
                    _process_image(img, None, items, cfg, out)
        except Exception as exc:  # a broken video: every head it should give is a reject
            done = {o[0] for o in out}
            out += [(it[0], f"no image (video {src}: {' '.join(str(exc).split())[:120]})", -1, -1, None)
                    for items in groups.values() for it in items if it[0] not in done]
        return out
    items = groups
    if src is None:
        return [(it[0], "no image (file not found)", -1, -1, None) for it in items]
    try:
        with open(src, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        return [(it[0], f"no image ({exc.strerror or exc})", -1, -1, None) for it in items]
    if cfg["full_frames"] and src.lower().endswith((".jpg", ".jpeg")):
        size = jpeg_size(data)
        if size is not None:  # copy the JPEG as is: no decode needed for the whole frame
            _process_image(_SizeOnly(size), data, items, cfg, out)
            return out
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    # keep this frame alive until the next one is decoded: freeing a multi-MB frame before the next allocation
    # makes every decode fault in fresh pages (measured: decoding 1080p JPEGs about 25% slower)
    _LAST_FRAME[0] = image
    if image is None:
        return [(it[0], "unreadable image", -1, -1, None) for it in items]
    _process_image(image, data if cfg["full_frames"] and src.lower().endswith((".jpg", ".jpeg")) else None,
                   items, cfg, out)
    return out


class _SizeOnly:
    """Stands in for a decoded image when only its size is needed (full frames copied as files)."""

    def __init__(self, size):
        self.shape = (size[1], size[0], 3)


# ----------------------------------------------------------------------------------------------- staging
@contextmanager
def staged_dir(path, overwrite: bool):
    """A temporary folder that becomes ``path`` when the run commits (``hpe_cli.io.transaction.staged_dir``).

    An export replaces a whole dataset: with ``overwrite``, files of an earlier export that this one did not
    write are removed after the commit (a stale shard or split folder would otherwise be read with the new
    ones).
    """
    from ..io.transaction import current
    from ..io.transaction import staged_dir as shared

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise HpeError(f"{path}: exists and is not a folder")
    if path.exists() and not overwrite:
        raise HpeError(f"{path}: already exists (use --overwrite to replace it)")
    with shared(path, overwrite) as tmp:
        tmp = Path(tmp)
        yield tmp
        if path.is_dir():
            keep = {p.relative_to(tmp) for p in tmp.rglob("*") if p.is_file()}
            txn = current()

            def prune():
                for p in sorted(path.rglob("*"), key=lambda q: len(q.parts), reverse=True):
                    rel = p.relative_to(path)
                    if p.is_file() or p.is_symlink():
                        if rel not in keep:
                            p.unlink(missing_ok=True)
                    elif p.is_dir() and not any(p.iterdir()):
                        p.rmdir()

            if txn is not None:
                txn.after_commit(prune)


CHOICE_PREFIXES = ("WHENet rule", "DirectMHP normalisation", "outside ±99", "min-change", "balance",
                   "image dropped", "no 2-D landmarks")


def is_choice(reason: str) -> bool:
    """A reject made by a rule the user chose (layout, sampling, split file), not by bad input."""
    return reason.startswith(CHOICE_PREFIXES) or reason.endswith("not listed in --split-file")


# ----------------------------------------------------------------------------------------------- the job
def run_export(inputs, output, opts: ExportOptions, progress=None) -> dict:
    """Export ``inputs`` to the folder ``output`` (see the module docstring). Returns the summary dict."""
    import pandas as pd

    from ..io import Rejects
    from ..rotation.convert import canonical_to_labels
    from ..rotation.systems import get_system

    output = Path(output)
    if output.exists() and not opts.overwrite:
        raise HpeError(f"{output}: already exists (use --overwrite to replace it)")
    for p in inputs:
        try:
            if Path(p).resolve() == output.resolve() or output.resolve() in Path(p).resolve().parents:
                raise HpeError(f"{output}: is an input (or holds one); choose another output folder")
        except OSError:
            pass
    rejects = Rejects(opts.rejects, opts.overwrite)
    layout = get_layout(opts.layout, system=opts.system, form=opts.form)
    if layout.system is not None and opts.system is not None and get_system(opts.system).name != layout.system:
        raise HpeError(f"--layout {layout.name} stores labels in the {layout.system} system, which its trainer "
                       f"expects; --system {get_system(opts.system).name} cannot be used with it")
    system = get_system(layout.system or opts.system or "300w_lp")

    rows = load_inputs(inputs, opts.images, opts.input_system, landmarks=layout.uses_landmarks)
    n = len(rows)
    reasons = rows["reason"].to_numpy(dtype=object).copy()
    A = rows[A_COLS].to_numpy(np.float64).reshape(n, 3, 3)
    conv = canonical_to_labels(A, system)
    ang = conv.primary
    ok = reasons == ""
    rule = layout.label_reasons(ang)
    reasons[ok & (rule != "")] = rule[ok & (rule != "")]
    n_lm = landmark_count(rows.columns)
    lm = (np.stack([rows[[f"lm{i}_{a}" for i in range(n_lm)]].to_numpy(np.float64) for a in "xy"], -1)
          if n_lm else np.full((n, 0, 2), np.nan))
    if layout.needs_landmarks:
        nolm = ~np.isfinite(lm).all(-1).any(1) if n_lm else np.ones(n, bool)
        reasons[(reasons == "") & nolm] = "no 2-D landmarks (the 6DRepNet .mat loader crops from pt2d)"

    # splits
    if opts.split and opts.split_file:
        raise HpeError("use --split or --split-file, not both")
    if opts.split_file:
        col, mapping = read_split_file(opts.split_file)
        if col not in rows.columns:
            raise HpeError(f"{opts.split_file}: group column {col!r} is not in the labels "
                           f"(expected one of sequence, subject, identity, person_id, camera, source, image)")
        split = rows[col].astype(str).map(mapping).to_numpy(dtype=object)
        miss = pd.isna(split)
        reasons[(reasons == "") & miss] = f"{col} not listed in --split-file"
        split = np.where(miss, "", split).astype(object)
    elif opts.split:
        col, names, fr = parse_split(opts.split)
        if col not in rows.columns:
            raise HpeError(f"--split: column {col!r} is not in the labels (expected one of sequence, subject, "
                           "identity, person_id, camera, source, image)")
        split = assign_splits(rows[col].astype(str).to_numpy(), names, fr, opts.seed)
    elif layout.name == "directmhp":
        from ..io.export.directmhp import default_splits

        split = default_splits(rows)
    else:
        split = np.full(n, "train", dtype=object)
    rows = rows.copy()
    rows["split"] = split

    # sampling
    notes = []
    if opts.min_change is not None:
        keys = (rows["source"].astype(str) + "\0" + rows["sequence"].astype(str) + "\0" +
                rows["person_id"].astype(str) + "\0" + rows["camera"].astype(str)).to_numpy()
        ok = reasons == ""
        keep = min_change_keep(keys, rows["frame"].to_numpy(), A, opts.min_change, ok)
        reasons[ok & ~keep] = f"min-change: within {opts.min_change:g} deg of the last kept sample"
        notes.append(f"--min-change {opts.min_change:g}: per (sequence, person, camera), in frame order, a sample "
                     f"is kept only if its rotation differs from the last kept one by more than {opts.min_change:g} "
                     "degrees (geodesic angle)")
    if opts.balance:
        bin_deg, mx = parse_balance(opts.balance)
        ok = reasons == ""
        keep, bins = balance_keep(ang[:, 1], bin_deg, mx, ok, opts.seed)
        lo = -180.0 + bins * bin_deg
        drop = ok & ~keep
        reasons[drop] = [f"balance: yaw bin [{a:g}, {a + bin_deg:g}) over {mx}" for a in lo[drop]]
        notes.append(f"--balance yaw:{bin_deg:g}:{mx} --seed {opts.seed}: at most {mx} samples per {bin_deg:g}-degree "
                     f"bin of {system.name} yaw, chosen at random with seed {opts.seed}")
    if opts.drop_images_with_rejects:
        img_key = (rows["source"].astype(str) + "\0" + rows["image"].astype(str)).to_numpy()
        bad_imgs = np.unique(img_key[reasons != ""])
        hit = (reasons == "") & np.isin(img_key, bad_imgs)
        reasons[hit] = "image dropped: another head in it has no label (--drop-images-with-rejects)"
        notes.append("--drop-images-with-rejects: an image is exported only if every head in it is")
    opts.sampling_notes = notes

    # crops
    scale = opts.crop_scale if opts.crop_scale is not None else 1.0
    square = layout.default_square if opts.square is None else opts.square
    size = opts.size if opts.size is not None else layout.default_size
    bbox = rows[BBOX_COLS].to_numpy(np.float64)
    cbox = layout.crop_boxes(rows, expand_boxes(np.nan_to_num(bbox, nan=0.0), scale, square), lm)
    ok = reasons == ""
    reasons[ok & ~np.isfinite(cbox).all(1)] = "no crop box"
    cbox = np.nan_to_num(cbox, nan=0.0)
    pbox = pixel_boxes(cbox)
    cw, ch = pbox[:, 2] - pbox[:, 0], pbox[:, 3] - pbox[:, 1]
    if size is not None:
        if square or layout.stretch:
            osz = np.stack([np.full(n, size), np.full(n, size)], 1)
        else:
            osz = np.stack([np.full(n, size), np.maximum(1, np.round(size * ch / np.maximum(cw, 1)))], 1)
    else:
        osz = np.stack([cw, ch], 1)
    osz = osz.astype(np.int64)

    todo = np.flatnonzero(reasons == "")
    if todo.size == 0:
        first = pd.Series(reasons).value_counts()
        raise HpeError(f"--layout {layout.name}: every label is rejected, nothing written "
                       f"({'; '.join(f'{r}: {c}' for r, c in first.items())})")

    rel = np.empty(n, dtype=object)
    for s in np.unique(split[todo]).tolist():
        idx = todo[split[todo] == s]
        rel[idx] = layout.relpath(rows.iloc[idx], s)
    # one task per source image (or per Panoptic video)
    roots = rows["root"].to_numpy(dtype=object)
    images = rows["image"].to_numpy(dtype=object)
    seqs = rows["sequence"].to_numpy(dtype=object)
    cams = rows["camera"].to_numpy(dtype=object)
    frames = rows["frame"].to_numpy()
    full_frames = layout.full_frames
    task_of = {}
    tasks = []
    for i in todo.tolist():
        key = (roots[i], images[i])
        t = task_of.get(key)
        if t is None:
            src = resolve_image(roots[i], images[i], seqs[i], cams[i], int(frames[i]))
            if src is None and cams[i] and frames[i] >= 0:
                vkey = ("video", roots[i], seqs[i], cams[i])
                t = task_of.get(vkey)
                if t is None:
                    t = task_of[vkey] = ["video", video_path(roots[i], seqs[i], cams[i]), {}]
                    tasks.append(t)
                task_of[key] = t
            else:
                t = task_of[key] = ["image", src, []]
                tasks.append(t)
        item = (i, split[i], rel[i], tuple(pbox[i].tolist()), tuple(bbox[i].tolist()),
                None if full_frames else tuple(osz[i].tolist()))
        if t[0] == "video":
            t[2].setdefault(int(frames[i]), []).append(item)
        else:
            t[2].append(item)

    status = np.full(n, "", dtype=object)
    order = np.full(n, -1, dtype=np.int64)
    W = rows["image_width"].to_numpy(np.float64).copy()
    H = rows["image_height"].to_numpy(np.float64).copy()
    splits_used = sorted(set(split[todo].tolist()))
    final_root = output.resolve()
    with staged_dir(output, opts.overwrite) as stage:
        layout.open(stage, splits_used)
        split_dirs = {s: str(layout.split_dir(s).relative_to(stage)) for s in splits_used}
        cfg = {"root": str(stage), "split_dirs": split_dirs, "quality": int(opts.quality),
               "pad_value": int(opts.pad_value), "min_inside": float(opts.min_inside),
               "full_frames": full_frames, "pixels": layout.pixels, "made": set()}
        counter = 0
        bar = progress(total=int(todo.size)) if progress else None
        try:
            if opts.workers > 1 and len(tasks) > 1:
                import multiprocessing as mp

                ctx = mp.get_context("spawn" if os.name == "nt" else "fork")
                pool = ctx.Pool(opts.workers, initializer=_init_worker, initargs=(cfg,))
                results = pool.imap(_work, [tuple(t) for t in tasks], chunksize=max(1, min(16, len(tasks) // (8 * opts.workers))))
            else:
                pool = None
                _init_worker(cfg)
                results = map(_work, [tuple(t) for t in tasks])
            try:
                for res, spill in results:
                    spill_fh = open(spill, "rb") if spill else None
                    good, payloads = [], []
                    for idx, reason, w, h, payload in res:
                        if w > 0:
                            W[idx], H[idx] = w, h
                        if reason:
                            status[idx] = reason
                        else:
                            order[idx] = counter
                            counter += 1
                            good.append(idx)
                            payloads.append(payload)
                            if spill_fh is not None and len(payloads) >= 256:  # flush in small slices
                                _add_pixels(layout, rows, good, payloads, split, spill_fh, ang, conv, rel, pbox,
                                            osz, W, H, lm)
                                good, payloads = [], []
                    if good and layout.pixels != "file":
                        _add_pixels(layout, rows, good, payloads, split, spill_fh, ang, conv, rel, pbox, osz, W, H,
                                    lm)
                    if spill_fh is not None:
                        spill_fh.close()
                        os.unlink(spill)
                    if bar is not None:
                        bar.update(len(res))
            finally:
                if pool is not None:
                    pool.close()
                    pool.join()
            img_rej = status != ""
            reasons[img_rej] = status[img_rej]
            done = np.flatnonzero((reasons == "") & (order >= 0))
            done = done[np.argsort(order[done], kind="stable")]
            if done.size == 0:
                c = pd.Series(reasons[todo]).value_counts()
                raise HpeError(f"--layout {layout.name}: no label could be exported, nothing written "
                               f"({'; '.join(f'{r}: {k}' for r, k in c.items())})")
            exported = _exported_frame(rows, done, ang, conv, rel, pbox, osz, W, H, lm)
            notes_extra = layout.finish(exported, final_root)
            if not layout.full_frames:
                # every crop's box in the source frame's pixels (exclusive ends) and its written size
                exported[["split", "file", "source", "image", "bbox_x", "bbox_y", "bbox_w", "bbox_h", "crop_x0",
                          "crop_y0", "crop_x1", "crop_y1", "out_w", "out_h", "image_width", "image_height"]].to_csv(
                    stage / "crops.csv", index=False)
            if layout.name == "hf":
                kinds = sorted(set(rows["kind"].iloc[done].tolist()))
                layout.write_card(exported, system, notes, {k: LICENCES.get(k, LICENCES["table"]) for k in kinds},
                                  final_root)
        except BaseException:
            layout.abort()
            raise
        finally:
            if bar is not None:
                bar.close()
        per_reason = pd.Series(reasons[reasons != ""]).value_counts().to_dict()
        per_split = exported["split"].value_counts().sort_index().to_dict()
        summary = {"layout": layout.name, "form": getattr(layout, "form", None), "system": system.name,
                   "system_description": system.describe(), "inputs": [str(p) for p in inputs],
                   "labels": int(n), "exported": int(len(exported)), "per_split": per_split,
                   "rejected": int((reasons != "").sum()), "rejects_per_reason": per_reason, "sampling": notes,
                   "crop": {"scale": scale, "square": bool(square), "size": None if size is None else int(size),
                            "jpeg_quality": int(opts.quality), "pad_value": int(opts.pad_value),
                            "min_inside": opts.min_inside},
                   "split": opts.split or (opts.split_file and f"file {opts.split_file}") or
                   ("DirectMHP's sequence lists" if layout.name == "directmhp" else "none (one split: train)"),
                   "seed": opts.seed, "notes": notes_extra}
        with open(stage / "export.json", "w", encoding="utf-8") as fh:
            json.dump(summary, fh, indent=1, default=str)
        # the rejects: every input label not exported, with its reason
        rej = np.flatnonzero(reasons != "")
        if rej.size:
            sub = rows.iloc[rej]
            rejects.add({"input": sub["input"].to_numpy(), "row": sub["row"].astype(str).to_numpy(),
                         "source": sub["source"].to_numpy(), "image": sub["image"].to_numpy(),
                         "sequence": sub["sequence"].to_numpy(), "camera": sub["camera"].to_numpy(),
                         "frame": sub["frame"].to_numpy(), "person_id": sub["person_id"].to_numpy(),
                         "split": rows["split"].to_numpy()[rej].astype(str)}, reasons[rej])
        # bad input (unusable rows, missing/unreadable images, boxes outside the frame) follows the rule of every
        # command: without --rejects (or with --strict) it is an error and nothing is written; the layout's own
        # rules, the sampling and the split file are choices, always counted in the summary
        from ..io.table_source import row_name

        bad = np.flatnonzero((reasons != "") & ~np.array([is_choice(r) for r in reasons], dtype=bool))
        if bad.size:
            from ..io.rejects import rejects_rule

            k = int(bad[0])
            first = f"{row_name(rows['input'].iat[k], rows['row'].iat[k])}: {reasons[k]}"
            rejects_rule(int(bad.size), first, has_file=rejects.path is not None, strict=opts.strict)
        if opts.strict and (reasons != "").any():
            k = int(np.flatnonzero(reasons != "")[0])
            raise HpeError(f"{row_name(rows['input'].iat[k], rows['row'].iat[k])}: {reasons[k]}; "
                           f"{int((reasons != '').sum())} label(s) not exported and --strict given: nothing written")
        rejects.write()
    summary["output"] = str(output)
    return summary


def _add_pixels(layout, rows, good, payloads, split, spill_fh, ang, conv, rel, pbox, osz, W, H, lm):
    """Hand one slice of finished heads (and their pixels) to the layout, split by split."""
    g = np.asarray(good)
    for s in sorted(set(split[g].tolist())):
        sel = [k for k, gi in enumerate(good) if split[gi] == s]
        sub = _exported_frame(rows, g[sel], ang, conv, rel, pbox, osz, W, H, lm)
        layout.add_pixels(s, sub, [_unspill(payloads[k], spill_fh) for k in sel])


def _exported_frame(rows, idx, ang, conv, rel, pbox, osz, W, H, lm):
    """The exported rows' metadata: labels in the layout system, boxes, crop box, sizes, landmarks."""
    import pandas as pd

    idx = np.asarray(idx, dtype=np.int64)
    sub = rows.iloc[idx]
    d = {c: sub[c].to_numpy() for c in ["split", "source", "kind", "image", "sequence", "camera", "frame",
                                        "person_id", "subject"] + BBOX_COLS}
    d["file"] = rel[idx]
    d["pitch"], d["yaw"], d["roll"] = ang[idx, 0], ang[idx, 1], ang[idx, 2]
    M = conv.matrix[idx].reshape(-1, 9)
    for k, c in enumerate(MATRIX_COLS):
        d[c] = M[:, k]
    for k, c in enumerate(["crop_x0", "crop_y0", "crop_x1", "crop_y1"]):
        d[c] = pbox[idx, k]
    d["out_w"], d["out_h"] = osz[idx, 0], osz[idx, 1]
    d["image_width"], d["image_height"] = W[idx], H[idx]
    for c in ("tdx", "tdy", "tdz", "scale"):
        if c in rows.columns:
            d[c] = sub[c].to_numpy(np.float64)
    for i in range(lm.shape[1]):
        d[f"lm{i}_x"], d[f"lm{i}_y"] = lm[idx, i, 0], lm[idx, i, 1]
    return pd.DataFrame(d)
