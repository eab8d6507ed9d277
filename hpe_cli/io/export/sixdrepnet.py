"""6DRepNet layouts, in its two forms.

``--form crops`` (crop-based full-range sets such as CMU Panoptic or AGORA), followed from hnuzhy/DirectMHP
``exps/gen_dataset_full_AGORA_CMU.py``, the script DirectMHP's README uses to train 6DRepNet full-range on
CMU/AGORA: each head box is cut from its frame and resized to ``img_size`` x ``img_size`` (256; the box is
stretched, not padded to a square, unless ``--square``) and saved as ``<data_dir>/<name>.jpg``; the list file
``files_<split>.txt`` (next to the split folder) has one line ``<name>.jpg pitch yaw roll`` per crop, the
angles being the COCO ``euler_angles`` (degrees, the ``whenet`` system, full range). 6DRepNet's ``get_R(pitch,
yaw, roll) = Rz(roll) Ry(yaw) Rx(pitch)`` of those angles is Aᵀ. Train with ``--data_dir OUT/<split>
--filename_list OUT/files_<split>.txt``. hpe writes the angles with full precision (DirectMHP: ``%.4f``).

``--form mat`` (300W-LP/AFLW2000-style sets), followed from thohemp/6DRepNet ``sixdrepnet/datasets.py``
(``Pose_300W_LP`` and ``AFLW2000``) and its ``utils.get_ypr_from_mat``/``get_pt2d_from_mat``: for each name
in the file list ``<split>/files.txt`` (one name per line, no extension, relative to the data folder), the
loader opens ``<name>.jpg`` and ``<name>.mat``, reads ``Pose_Para[0][:3]`` as pitch, yaw, roll in radians
and builds ``get_R(pitch, yaw, roll)``, and crops loosely around ``min/max`` of ``pt2d``. So each ``.mat``
holds ``Pose_Para`` (1 x 7: pitch, yaw, roll in radians, then tdx, tdy, tdz, scale, NaN where the source has
none) and ``pt2d`` (2 x K, **only the visible points**, in the written image's pixels: an invisible AFLW2000
point stored as -1 would pull the loader's min/max box to the image corner). The written image is a crop
around the landmarks wide enough for the loaders' loosest crops (which grow ``x_max``/``y_max`` from the
already-moved ``x_min``/``y_min``): training, k = 0.4: 0.24 w left, 0.30 w right, 0.8 h above, 0.43 h below;
AFLW2000 test, k = 0.2: 0.4 w left, 0.56 w right, 0.4 h above, 0.17 h below. The margins are 0.5 w left,
0.65 w right, 0.9 h above and 0.5 h below the visible landmarks. Hopenet and
6DRepNet keep only labels within ±99° (their bins run from -99 to 102); labels outside are rejects.
"""
from __future__ import annotations

import numpy as np

from ...geometry.crop import landmark_boxes, points_to_crop
from .base import Layout, abs_over

RULE_99 = "outside ±99° (the 6DRepNet/Hopenet filter)"
#: landmark-box margins of the ``mat`` form's crop (fractions of the landmark box: left, top, right, bottom)
MAT_MARGINS = (0.5, 0.9, 0.65, 0.5)


class SixDRepNetLayout(Layout):
    name = "6drepnet"
    system = "6drepnet"

    def __init__(self, system=None, form=None, **options):
        super().__init__(system, form or "crops", **options)
        if self.form not in ("crops", "mat"):
            raise ValueError(f"expected --form crops or mat, got {self.form!r}")
        self.needs_landmarks = self.uses_landmarks = self.form == "mat"
        if self.form == "crops":  # DirectMHP's full-range 6DRepNet data: COCO euler_angles, 256 x 256 crops
            self.system = "whenet"
            self.default_size = 256
            self.stretch = True

    def label_reasons(self, angles):
        if self.form == "mat":
            return np.where(abs_over(angles, 99.0), RULE_99, "").astype(object)
        return np.full(len(angles), "", dtype=object)

    def crop_boxes(self, rows, boxes, landmarks):
        if self.form != "mat":
            return boxes
        t = landmark_boxes(landmarks)
        ml, mt, mr, mb = MAT_MARGINS
        return np.stack([t[:, 0] - ml * t[:, 2], t[:, 1] - mt * t[:, 3],
                         t[:, 2] * (1 + ml + mr), t[:, 3] * (1 + mt + mb)], axis=1)

    def finish(self, exported, final_root):
        if self.form == "crops":
            for split, part in exported.groupby("split", sort=True):
                ang = part[["pitch", "yaw", "roll"]].to_numpy(dtype=np.float64).tolist()
                lines = [f"{f} {p!r} {y!r} {r!r}\n" for f, (p, y, r) in zip(part["file"].tolist(), ang)]
                with open(self.root / f"files_{split}.txt", "w", encoding="utf-8", newline="") as fh:
                    fh.writelines(lines)
            return []
        import scipy.io

        from ...io.layout import landmark_count

        n_lm = landmark_count(exported.columns)
        for split, part in exported.groupby("split", sort=True):
            names = []
            lm = np.stack([part[[f"lm{i}_{a}" for i in range(n_lm)]].to_numpy(dtype=np.float64)
                           for a in "xy"], -1)
            box = part[["crop_x0", "crop_y0", "crop_x1", "crop_y1"]].to_numpy(dtype=np.int64)
            size = part[["out_w", "out_h"]].to_numpy(dtype=np.int64)
            rad = np.deg2rad(part[["pitch", "yaw", "roll"]].to_numpy(dtype=np.float64))
            td = part[["tdx", "tdy", "tdz", "scale"]].to_numpy(dtype=np.float64) if "tdx" in part \
                else np.full((len(part), 4), np.nan)
            heights = part["image_height"].to_numpy(dtype=np.float64)
            for k, f in enumerate(part["file"].tolist()):
                name = f[:-4]
                pts = points_to_crop(lm[k:k + 1], box[k:k + 1], tuple(size[k]))[0]
                pts = pts[np.isfinite(pts).all(1)]
                # tdx/tdy: the projection centre in the written image (tdy counts from the bottom, SPEC §8)
                sx = size[k, 0] / (box[k, 2] - box[k, 0])
                sy = size[k, 1] / (box[k, 3] - box[k, 1])
                row = heights[k] - 1 - td[k, 1]
                tdx = (td[k, 0] - box[k, 0] + 0.5) * sx - 0.5
                tdy = size[k, 1] - 1 - ((row - box[k, 1] + 0.5) * sy - 0.5)
                pose = np.array([[rad[k, 0], rad[k, 1], rad[k, 2], tdx, tdy, td[k, 2], td[k, 3]]])
                scipy.io.savemat(self.split_dir(split) / f"{name}.mat",
                                 {"Pose_Para": pose, "pt2d": np.ascontiguousarray(pts.T)}, do_compression=False)
                names.append(name + "\n")
            with open(self.split_dir(split) / "files.txt", "w", encoding="utf-8", newline="") as fh:
                fh.writelines(names)
        return []
