"""DAD-3DHeads (Martyniuk et al., CVPR 2022) label files.

Layout, as the dataset's README and ``model_training/data/flame_dataset.py`` /
``dad_3dheads_benchmark/generate_gt.py`` (PinataFarms/DAD-3DHeads) read it::

    DAD-3DHeadsDataset/{train,val,test}/
        <subset>.json               list of {item_id, annotation_path, img_path,
                                    bbox: [x, y, w, h], attributes: {quality, gender,
                                    expression, age, occlusions, pose, standard light}}
        images/<ID>.png
        annotations/<ID>.json       {vertices (5023 x 3 FLAME), model_view_matrix (4 x 4),
                                    projection_matrix (4 x 4)}   (no annotations for test)

The head pose is the rotation block of the OpenGL model-view matrix
``MV`` (FLAME model frame -> camera frame, camera looking down -z with y up).
``hpe`` stores the ``dad3dheads`` label as ``R = diag(1, -1, -1) @ MV[:3, :3] / s``
(``s = det(MV[:3, :3]) ** (1/3)``, 1 for a pure rotation): the same rotation
seen from an OpenCV camera (y down, z forward). This is the ground truth the
dataset's benchmark compares predictions with
(``dad_3dheads_benchmark/benchmark.py``, ``DADEvaluator.get_gt_rot_mat``:
``(diag(1, -1, -1, 1) @ MV)[:3, :3]``); the benchmark does not divide by
``s``, so the two agree exactly when the model-view matrix has no scale
(``mv_scale`` = 1, which the column lets you check).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError
from .fields import as_numbers, describe, member_problem
from .jsonfile import load_json

SYSTEM = "dad3dheads"
SUBSETS = ("train", "val", "test")
FLIP_YZ = np.diag([1.0, -1.0, -1.0])
ATTRIBUTES = ("quality", "gender", "expression", "age", "occlusions", "pose", "standard light")


def is_dad_metadata(doc) -> bool:
    """A ``<subset>.json`` list: objects with ``item_id`` and ``bbox``."""
    return isinstance(doc, list) and bool(doc) and isinstance(doc[0], dict) and "item_id" in doc[0] and "bbox" in doc[0]


def model_view_to_matrix(mv) -> tuple:
    """``(R, s)``: ``R = diag(1,-1,-1) @ MV[:3,:3] / s`` for ``(N, 4, 4)`` model-view matrices, ``s`` the scale."""
    mv = np.asarray(mv, dtype=np.float64)
    if mv.shape[-2:] != (4, 4):
        raise ValueError(f"expected (N, 4, 4) model-view matrices, got {mv.shape}")
    M = mv[..., :3, :3]
    det = np.linalg.det(M)
    s = np.cbrt(det)
    with np.errstate(divide="ignore", invalid="ignore"):
        R = FLIP_YZ @ (M / s[..., None, None])
    return R, s


def _metadata_files(path: Path):
    """[(subset, metadata json path)] for a root, a subset folder, or a metadata file."""
    if path.is_file():
        return [(path.stem, path)]
    own = path / f"{path.name}.json"
    if own.is_file():
        return [(path.name, own)]
    out = [(s, path / s / f"{s}.json") for s in SUBSETS if (path / s / f"{s}.json").is_file()]
    return out


def is_dad3dheads(path) -> bool:
    path = Path(path)
    if path.is_dir():
        return bool(_metadata_files(path))
    if path.is_file() and path.suffix.lower() == ".json" and path.stem in SUBSETS:
        try:
            return is_dad_metadata(load_json(path))
        except HpeError:
            return False
    return False


def _item_fields(it: dict, where: str, subset: str):
    """``(item_id, image, bbox (4,), attributes)`` of one metadata item, each field's type checked at the door."""

    iid = it["item_id"]
    if isinstance(iid, bool) or not isinstance(iid, (str, int)) or str(iid) == "":
        raise HpeError(f"{where}: item_id: expected a non-empty string, got {describe(iid)}")
    iid = str(iid)
    if "/" in iid or "\\" in iid or "\x00" in iid or iid in (".", ".."):
        raise HpeError(f"{where}: item_id: expected a file name (it names annotations/<item_id>.json), got {iid!r}")
    image = it.get("img_path", f"{subset}/images/{iid}.png")
    if not isinstance(image, str) or not image or member_problem(image):
        why = member_problem(image) if isinstance(image, str) and image else ""
        raise HpeError(f"{where}: img_path: expected a relative image path, got {why or describe(image)}")
    box = np.full(4, np.nan)
    b = it.get("bbox")
    if b is not None:
        arr, got = as_numbers(b, (4,)) if isinstance(b, list) else (None, f"got {describe(b)}")
        if arr is None:
            raise HpeError(f"{where}: bbox: expected [x, y, w, h] (4 numbers), {got}")
        box = arr
    at = it.get("attributes")
    if at is None:
        at = {}
    if not isinstance(at, dict):
        raise HpeError(f"{where}: attributes: expected an object, got {describe(at)}")
    for a in ATTRIBUTES:
        v = at.get(a)
        if isinstance(v, (list, dict)):
            raise HpeError(f"{where}: attributes.{a}: expected a value (string or number), got {describe(v)}")
    return iid, image, box, at


def _model_view(ann: Path) -> np.ndarray:
    """The 4 x 4 ``model_view_matrix`` of one annotation file (numbers only)."""

    doc = load_json(ann)
    if not isinstance(doc, dict) or doc.get("model_view_matrix") is None:
        raise HpeError(f"{ann}: expected model_view_matrix as 4 x 4 numbers, got none")
    arr, got = as_numbers(doc["model_view_matrix"], (4, 4))
    if arr is None:
        raise HpeError(f"{ann}: expected model_view_matrix as 4 x 4 numbers, {got}")
    return arr


def read_dad3dheads(path, with_lines: bool = False):
    """Read DAD-3DHeads labels into a table (``attrs["system"] == "dad3dheads"``).

    ``path`` is the dataset root (with ``train/``, ``val/``, ...), one subset
    folder, or a ``<subset>.json`` metadata file.

    Columns: ``item_id``, ``subset``, ``image`` (``img_path``),
    ``bbox_x, bbox_y, bbox_w, bbox_h`` (``bbox = [x, y, w, h]``), one column
    per attribute (``standard light`` -> ``standard_light``), ``r00..r22``
    (the ``dad3dheads`` label ``diag(1,-1,-1) @ MV[:3,:3] / s``),
    ``mv_scale`` (``s``), ``mv00..mv33`` (the model-view matrix as stored) and
    ``__line__`` (1-based item position in its metadata file). Items without
    an annotation file (the test subset) get NaN labels and are reported by
    the label validation as missing values.
    """
    import pandas as pd

    path = Path(path)
    metas = _metadata_files(path)
    if not metas:
        raise HpeError(
            f"{path}: expected a DAD-3DHeads folder (train/train.json, val/val.json, ... or "
            "<subset>.json with annotations/<ID>.json)"
        )
    frames = []
    for subset, meta in metas:
        items = load_json(meta)
        if not is_dad_metadata(items) and items != []:
            raise HpeError(f"{meta}: expected a list of objects with item_id and bbox")
        base = meta.parent
        n = len(items)
        cols = {"item_id": [], "subset": [subset] * n, "image": []}
        attrs = {a: [] for a in ATTRIBUTES}
        box = np.full((n, 4), np.nan)
        mv = np.full((n, 4, 4), np.nan)
        for k, it in enumerate(items):
            where = f"{meta}: item {k + 1}"
            if not isinstance(it, dict) or "item_id" not in it:
                raise HpeError(f"{where}: expected an object with item_id")
            iid, image, box[k], at = _item_fields(it, where, subset)
            cols["item_id"].append(iid)
            cols["image"].append(image)
            for a in ATTRIBUTES:
                v = at.get(a)
                attrs[a].append(None if v is None else str(v))
            ann = base / "annotations" / f"{iid}.json"
            if ann.is_file():
                mv[k] = _model_view(ann)
        f = pd.DataFrame(cols)
        for i, c in enumerate(("bbox_x", "bbox_y", "bbox_w", "bbox_h")):
            f[c] = box[:, i]
        for a in ATTRIBUTES:
            f[a.replace(" ", "_")] = attrs[a]
        R, s = model_view_to_matrix(mv) if n else (np.zeros((0, 3, 3)), np.zeros(0))
        for i in range(3):
            for j in range(3):
                f[f"r{i}{j}"] = R[:, i, j]
        f["mv_scale"] = s
        for i in range(4):
            for j in range(4):
                f[f"mv{i}{j}"] = mv[:, i, j]
        f["__line__"] = np.arange(1, n + 1, dtype=np.int64)
        frames.append(f)
    out = pd.concat(frames, ignore_index=True)
    if not with_lines:
        out = out.drop(columns=["__line__"])
    out.attrs["system"] = SYSTEM
    return out
