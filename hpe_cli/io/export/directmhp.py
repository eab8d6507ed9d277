"""DirectMHP layout: full frames, COCO JSON, YOLO label files and a data ``.yaml`` with no absolute path.

Followed (hnuzhy/DirectMHP@a51b06bc, the current code):
- ``train.py:98-99``: ``check_dataset(data)`` then ``data_dict['train']``, ``data_dict['val']``; ``val.py:86`` builds
  the loader from ``data[task]`` and ``data['labels']``, ``val.py:177`` opens
  ``osp.join(data['path'], data['<task>_annotations'])`` for the COCO mAP and the MAE. So both a ``train`` and a
  ``val`` split are required (an export without them is an error asking for ``--split``).
- ``utils/general.py:282-285`` (``check_dataset``): ``path`` (default ``''``) is joined to each split entry;
  ``utils/datasets.py:394-407``: a split entry that is a folder is globbed; ``:371-372`` (``img2label_paths``):
  the label file is the image path with ``images`` replaced by the ``labels`` folder and ``.txt``;
  ``:889-933`` (``verify_image_label``): a label line with a negative value drops the image.
- ``exps/CMU/data_split_hpe.py``: the 17 CMU sequence names (:data:`SEQ_NAMES`), its train/val lists, and the
  image id it decodes, ``seq_num = (image_id - 10000000000) // 100000000 - 1``. So a CMU image id is ``1`` + the
  2-digit sequence number (1-based index in :data:`SEQ_NAMES`) + the 6-digit frame + the 2-digit camera node,
  e.g. ``10400060013`` (hd_00_13, frame 600 of 170221_haggling_m3). Sequences not in that list are numbered after
  it in name order (18, 19, ...; listed in ``export.json``). Images without a Panoptic sequence/camera/frame get
  ids ``20000000000 + k`` (k = 1, 2, ... in input order). ``val.py:181`` evaluates ``int(Path(file).stem)`` as the
  image id, so the image file is ``images/<split>/<id>.jpg``.
- ``utils/labels.py:40-55``: COCO ``annotations/coco_style_<split>.json`` with DirectMHP's keys (``bbox``,
  ``euler_angles`` = [pitch, yaw, roll] degrees in the ``whenet`` system, ``face2d_pts``, ``area``, ``iscrowd``,
  ``segmentation``), and one YOLO line per head in ``yolov5_labels_coco/<split>/<id>.txt``:
  ``0 xc yc w h pitch/180+0.5 yaw/360+0.5 roll/180+0.5`` (6 decimals).
- ``data/cmu_panoptic_coco.yaml``: the keys of the data ``.yaml`` (path, labels, train, val, train_annotations,
  val_annotations, nc, num_angles, names). hpe writes ``path: .`` and ``<split>: images/<split>`` (see
  :func:`_write_yaml`): nothing in the export names its absolute location.
- labels with |pitch| > 90 or |roll| > 90 cannot be held in [0, 1] (utils/labels.py:48-50); the whenet primary
  solution keeps them inside, so the rule only guards. The box is clamped to the image (a box less than half
  inside the frame is a reject).
"""

from __future__ import annotations

import json

import numpy as np

from ...io.layout import landmark_count
from . import LAYOUTS
from .base import Layout

SEQ_NAMES = [
    "171204_pose3",
    "171026_pose3",
    "170221_haggling_b3",
    "170221_haggling_m3",
    "170224_haggling_a3",
    "170228_haggling_b1",
    "170404_haggling_a1",
    "170407_haggling_a2",
    "170407_haggling_b2",
    "171026_cello3",
    "161029_piano4",
    "160422_ultimatum1",
    "160224_haggling1",
    "170307_dance5",
    "160906_ian1",
    "170915_office1",
    "160906_pizza1",
]
SEQ_TRAIN = [
    "171204_pose3",
    "161029_piano4",
    "160422_ultimatum1",
    "170307_dance5",
    "160906_pizza1",
    "170221_haggling_b3",
    "170224_haggling_a3",
    "170404_haggling_a1",
    "170407_haggling_b2",
]
SEQ_VAL = [
    "171026_pose3",
    "171026_cello3",
    "160224_haggling1",
    "160906_ian1",
    "170915_office1",
    "170221_haggling_m3",
    "170228_haggling_b1",
    "170407_haggling_a2",
]
RULE = "DirectMHP normalisation: |pitch| > 90 or |roll| > 90 cannot be held in [0, 1]"
CATEGORIES = [{"supercategory": "person", "id": 1, "name": "person"}]


def sequence_numbers(sequences) -> dict:
    """1-based sequence number of each name: DirectMHP's 17, then the others in name order."""
    known = {s: k + 1 for k, s in enumerate(SEQ_NAMES)}
    extra = sorted({str(s) for s in sequences if s and str(s) not in known})
    out = dict(known)
    for k, s in enumerate(extra):
        out[s] = len(SEQ_NAMES) + 1 + k
    if len(out) > 99:
        raise ValueError(f"expected at most 99 sequences for DirectMHP's 2-digit number, got {len(out)}")
    return out


def image_ids(rows) -> np.ndarray:
    """DirectMHP image ids (int64) for each row (rows of one image share the id)."""
    seq = rows["sequence"].astype(str).to_numpy()
    cam = rows["camera"].astype(str).to_numpy()
    frame = rows["frame"].to_numpy(dtype=np.int64)
    nums = sequence_numbers(seq)
    ids = np.zeros(len(rows), dtype=np.int64)
    node = np.array([int(c.split("_")[-1]) if c and c.split("_")[-1].isdigit() else -1 for c in cam])
    cmu = (node >= 0) & (node < 100) & (frame >= 0) & (frame < 1_000_000) & (seq != "")
    ids[cmu] = (
        10_000_000_000
        + np.array([nums[s] for s in seq[cmu]], dtype=np.int64) * 100_000_000
        + frame[cmu] * 100
        + node[cmu]
    )
    if (~cmu).any():
        key = rows["source"].astype(str).to_numpy()[~cmu] + "\0" + rows["image"].astype(str).to_numpy()[~cmu]
        _, first, inv = np.unique(key, return_index=True, return_inverse=True)
        rank = np.empty(first.size, dtype=np.int64)
        rank[np.argsort(first, kind="stable")] = np.arange(first.size)
        ids[~cmu] = 20_000_000_000 + 1 + rank[inv.reshape(-1)]
    return ids


def default_splits(rows) -> np.ndarray:
    """DirectMHP's own split by sequence (``data_split_hpe.py``); other sequences go to train."""
    seq = rows["sequence"].astype(str).to_numpy()
    return np.where(np.isin(seq, SEQ_VAL), "val", "train").astype(object)


@LAYOUTS.register()
class DirectMHPLayout(Layout):
    name = "directmhp"
    default_split_note = "DirectMHP's sequence lists"
    system = "whenet"
    loader = (
        "hnuzhy/DirectMHP@a51b06bc train.py:98-99, val.py:86,177, utils/general.py:282-285, "
        "utils/datasets.py:371-372,394-407,889-933"
    )
    full_frames = True
    uses_landmarks = True

    def default_splits(self, rows):
        return default_splits(rows)

    def label_reasons(self, angles):
        bad = (np.abs(angles[:, 0]) > 90) | (np.abs(angles[:, 2]) > 90)
        return np.where(bad, RULE, "").astype(object)

    def relpath(self, rows, split):
        return np.array([f"{i}.jpg" for i in image_ids(rows).tolist()], dtype=object)

    def split_dir(self, split):
        return self.root / "images" / split

    def check_splits(self, splits):
        """DirectMHP's ``train.py:99`` reads ``data_dict['train']`` and ``data_dict['val']``, and ``val.py:177`` the
        ``val_annotations`` COCO file for the MAE: an export without both splits cannot be trained on."""
        missing = [s for s in ("train", "val") if s not in splits]
        if missing:
            raise ValueError(
                f"--layout directmhp: DirectMHP's train.py reads data['train'] and data['val'] (and val.py the "
                f"val COCO annotations for its MAE), but this export has no {' and no '.join(missing)} split "
                f"(got {', '.join(splits) or 'none'}); give --split, e.g. --split sequence:train=0.8,val=0.2 "
                "(or camera:/image: for one sequence), or a --split-file naming train and val"
            )

    def finish(self, exported, final_root):

        root = self.root
        (root / "annotations").mkdir(exist_ok=True)
        n_lm = landmark_count(exported.columns)
        splits = sorted(exported["split"].unique().tolist())
        for split in splits:
            part = exported[exported["split"] == split]
            ids = np.array([int(f[:-4]) for f in part["file"].tolist()], dtype=np.int64)
            W = part["image_width"].to_numpy(dtype=np.float64)
            H = part["image_height"].to_numpy(dtype=np.float64)
            box = _clamped_boxes(part, W, H)
            ang = part[["pitch", "yaw", "roll"]].to_numpy(dtype=np.float64)
            _write_coco(root / "annotations" / f"coco_style_{split}.json", part, ids, W, H, box, ang, n_lm)
            _write_yolo(root / "yolov5_labels_coco" / split, ids, W, H, box, ang)
        _write_yaml(root / "data.yaml", splits)
        nums = sequence_numbers(exported["sequence"].astype(str).unique())
        extra = {s: n for s, n in nums.items() if s not in SEQ_NAMES}
        notes = [
            f"read by {self.loader}",
            (
                "data.yaml has path: . (DirectMHP's check_dataset joins it to the working folder): run DirectMHP's "
                "train.py/val.py from the export folder with --data data.yaml, or set path: to where the export is"
            ),
        ]
        return notes + ([f"DirectMHP sequence numbers after its 17: {extra}"] if extra else [])


def _clamped_boxes(part, W, H):
    b = part[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy(dtype=np.float64)
    x0, y0 = np.clip(b[:, 0], 0, W), np.clip(b[:, 1], 0, H)
    x1, y1 = np.clip(b[:, 0] + b[:, 2], 0, W), np.clip(b[:, 1] + b[:, 3], 0, H)
    return np.stack([x0, y0, x1 - x0, y1 - y0], 1)


def _write_coco(path, part, ids, W, H, box, ang, n_lm):
    """COCO JSON with DirectMHP's keys (``utils/labels.py:40-47`` reads ``bbox`` and ``euler_angles``)."""
    if n_lm:
        xs = part[[f"lm{i}_x" for i in range(n_lm)]].to_numpy(dtype=np.float64)
        ys = part[[f"lm{i}_y" for i in range(n_lm)]].to_numpy(dtype=np.float64)
        gone = ~(np.isfinite(xs) & np.isfinite(ys))
        pts = [[x, y] for x, y in zip(np.where(gone, -1.0, xs).tolist(), np.where(gone, -1.0, ys).tolist())]
    else:
        pts = [[] for _ in range(len(part))]
    uniq, first = np.unique(ids, return_index=True)
    seqs = part["sequence"].astype(str).to_numpy()
    images = [
        {
            "file_name": f"{i}.jpg",
            "height": int(H[k]),
            "width": int(W[k]),
            "id": int(i),
            **({"seq": seqs[k]} if seqs[k] else {}),
        }
        for i, k in zip(uniq.tolist(), first.tolist())
    ]
    box_l, ang_l, area = box.tolist(), ang.tolist(), np.round(box[:, 2] * box[:, 3], 4).tolist()
    anns = [
        {
            "image_id": int(ids[k]),
            "id": k + 1,
            "category_id": 1,
            "bbox": box_l[k],
            "euler_angles": ang_l[k],
            "face2d_pts": pts[k],
            "area": area[k],
            "iscrowd": 0,
            "segmentation": [],
        }
        for k in range(len(part))
    ]
    coco = {
        "info": {"description": "hpe export --layout directmhp", "version": "1.0"},
        "licenses": [],
        "images": images,
        "annotations": anns,
        "categories": CATEGORIES,
    }
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(coco, fh)


def _write_yolo(folder, ids, W, H, box, ang):
    """YOLO label files, exactly ``utils/labels.py:40-55``'s arithmetic and format."""
    folder.mkdir(parents=True, exist_ok=True)
    xc, yc = (box[:, 0] + box[:, 2] / 2) / W, (box[:, 1] + box[:, 3] / 2) / H
    w, h = box[:, 2] / W, box[:, 3] / H
    p, y, r = ang[:, 0] / 180 + 0.5, ang[:, 1] / 360 + 0.5, ang[:, 2] / 180 + 0.5
    lines: dict = {}
    for k, i in enumerate(ids.tolist()):
        lines.setdefault(i, []).append(
            f"{0} {xc[k]:.6f} {yc[k]:.6f} {w[k]:.6f} {h[k]:.6f} {p[k]:.6f} {y[k]:.6f} {r[k]:.6f}\n"
        )
    for i, ls in lines.items():
        with open(folder / f"{i}.txt", "w", encoding="utf-8", newline="") as fh:
            fh.writelines(ls)


def _write_yaml(path, splits):
    """The data ``.yaml`` (keys of DirectMHP's ``data/cmu_panoptic_coco.yaml``), with no absolute path.

    ``path: .`` and, per split, the image folder ``images/<split>``: ``utils/general.py:282-285``
    (``check_dataset``) joins ``path`` and the split entry, ``utils/datasets.py:396-398`` globs a folder entry, and
    ``utils/datasets.py:371-372`` (``img2label_paths``) finds each label by replacing ``images`` with the ``labels``
    folder; ``val.py:177`` joins ``path`` and ``<split>_annotations``. (DirectMHP's own image lists hold absolute
    paths, and its ``./`` list entries resolve against the list's own folder, so a list could not be moved.)
    """
    yaml = [
        "# written by hpe export --layout directmhp (keys of DirectMHP data/cmu_panoptic_coco.yaml)",
        "# path: . is the working folder (check_dataset): run train.py/val.py from this folder,",
        "# or set path: to this folder's location",
        "path: .",
        "labels: yolov5_labels_coco",
    ]
    yaml += [f"{split}: images/{split}" for split in splits]
    yaml += [f"{split}_annotations: annotations/coco_style_{split}.json" for split in splits]
    yaml += ["", "nc: 1", "num_angles: 3", "names: [ 'person' ]", ""]
    path.write_text("\n".join(yaml), encoding="utf-8")
