"""6DRepNet layouts (also read by Hopenet and 6DRepNet360), in two forms.

Peer code followed (``repo@commit file:lines``):

- thohemp/6DRepNet@464b2ba5 ``sixdrepnet/datasets.py:15-21`` (``get_list_from_filenames``), ``:24-72``
  (``AFLW2000``) and ``:230-300`` (``Pose_300W_LP``, the class ``sixdrepnet/train.py:112-113`` trains on), with
  ``sixdrepnet/utils.py:100-114`` (``get_ypr_from_mat``/``get_pt2d_from_mat``) and ``:192-220`` (``get_R``);
- thohemp/6DRepNet360@b06e4fed ``sixdrepnet360/datasets.py`` (the same classes, byte for byte but for one
  import line: ``AFLW2000`` :24-72, ``Pose_300W_LP`` :230-300);
- natanielruiz/deep-head-pose@f7bbb998 ``code/datasets.py:80-145`` (Hopenet's ``Pose_300W_LP``) and
  ``:226-274`` (``AFLW2000``);
- hnuzhy/DirectMHP@a51b06bc ``exps/gen_dataset_full_AGORA_CMU.py:108-123`` (writer) and its 6DRepNet fork
  ``exps/sixdrepnet.zip:sixdrepnet/datasets.py:307-361`` (``Pose_AGORA_CMU``, reader) for ``--form crops``.

``--form mat`` (the default; the form every loader above but DirectMHP's fork reads): each loader reads a file
list whose lines are stems (``get_list_from_filenames``: ``f.read().splitlines()``), opens
``<data_dir>/<stem>.jpg`` and ``<data_dir>/<stem>.mat``, takes ``Pose_Para[0][:3]`` as pitch, yaw, roll in
radians (Hopenet: times 180/pi, degrees), builds ``get_R(pitch, yaw, roll) = Rz(roll) Ry(yaw) Rx(pitch)``
(6DRepNet/6DRepNet360), and crops loosely around ``min/max`` of ``pt2d``. So hpe writes, per split,
``<split>/<stem>.jpg``, ``<split>/<stem>.mat`` and the list ``<split>/files.txt`` (one stem per line; train with
``--data_dir OUT/<split> --filename_list OUT/<split>/files.txt``). Each ``.mat`` holds ``Pose_Para`` (1 x 7:
pitch, yaw, roll in radians, then tdx, tdy, tdz, scale, NaN where the source has none) and ``pt2d`` (2 x K,
**only the visible points**, in the written image's pixels: an invisible AFLW2000 point stored as -1 would pull
the loader's min/max box to the image corner). The written image is a crop around the landmarks wide enough
for the loaders' loosest crops (which grow ``x_max``/``y_max`` from the already-moved ``x_min``/``y_min``):
training, k = 0.4: 0.24 w left, 0.30 w right, 0.8 h above, 0.43 h below; AFLW2000 test, k = 0.2: 0.4 w left,
0.56 w right, 0.4 h above, 0.17 h below. The margins are 0.5 w left, 0.65 w right, 0.9 h above and 0.5 h below
the visible landmarks.

The range each trainer reads (``--trainer``; never one trainer's rule for all):

- ``hopenet``: Hopenet bins every angle with ``np.digitize([yaw, pitch, roll], range(-99, 102, 3)) - 1``
  (``code/datasets.py:134-136``) into 66 classes (``code/train_hopenet.py:91``), so only -99 <= angle < 99 gives a
  valid class; other labels are rejects.
- ``6drepnet`` (the default of ``--form mat``): the training class ``Pose_300W_LP`` reads any angle (``get_R``,
  no filter), but 6DRepNet's file lists come from ``sixdrepnet/create_filename_list.py:47-59``, which lists only
  ``abs(pitch), abs(yaw), abs(roll) <= 99`` degrees; hpe applies that rule (the list 6DRepNet's README makes).
- ``6drepnet360``: full range, no rule (6DRepNet360 trains on the back of the head; its classes read any angle).

``--form crops`` (full-range crop sets such as CMU Panoptic or AGORA): DirectMHP's script cuts each head box from
its frame, resizes it to ``img_size`` x ``img_size`` (256; stretched, not padded, unless ``--square``), saves
``<data_dir>/<name>.jpg``, and writes ``files_<split>.txt`` lines ``<name>.jpg pitch yaw roll`` (degrees, the COCO
``euler_angles``, the ``whenet`` system, full range); its fork's ``Pose_AGORA_CMU`` splits each line on one space,
joins ``data_dir`` and the name, and builds ``get_R`` of the angles in radians. No range rule (the fork reads any
angle) unless ``--trainer`` names one. hpe writes the angles with full precision (DirectMHP: ``%.4f``).
"""

from __future__ import annotations

import io

import numpy as np

from ...errors import HpeError
from ...geometry.crop import landmark_boxes, points_to_crop
from ...io.layout import landmark_count
from . import LAYOUTS
from .base import Layout, abs_over

TRAINERS = ("hopenet", "6drepnet", "6drepnet360")
RULE_HOPENET = "Hopenet bins: an angle outside [-99, 99) has no class (deep-head-pose code/datasets.py:134-136)"
RULE_6DREPNET = (
    "6DRepNet create_filename_list.py: |angle| > 99 is not listed (--trainer 6drepnet360 keeps the full range)"
)
#: loaders named in export.json, per form and trainer
LOADERS = {
    ("mat", "6drepnet"): "thohemp/6DRepNet@464b2ba5 sixdrepnet/datasets.py:230-300 (Pose_300W_LP), :24-72 "
    "(AFLW2000); list rule sixdrepnet/create_filename_list.py:47-59",
    ("mat", "6drepnet360"): "thohemp/6DRepNet360@b06e4fed sixdrepnet360/datasets.py:230-300 (Pose_300W_LP), "
    ":24-72 (AFLW2000)",
    ("mat", "hopenet"): "natanielruiz/deep-head-pose@f7bbb998 code/datasets.py:80-145 (Pose_300W_LP), :226-274 "
    "(AFLW2000)",
    ("crops", None): "hnuzhy/DirectMHP@a51b06bc exps/sixdrepnet.zip:sixdrepnet/datasets.py:307-361 "
    "(Pose_AGORA_CMU); writer exps/gen_dataset_full_AGORA_CMU.py:108-123",
}
#: landmark-box margins of the ``mat`` form's crop (fractions of the landmark box: left, top, right, bottom)
MAT_MARGINS = (0.5, 0.9, 0.65, 0.5)


@LAYOUTS.register()
class SixDRepNetLayout(Layout):
    name = "6drepnet"
    system = "6drepnet"
    forms = ("mat", "crops")
    trainers = TRAINERS

    def __init__(self, system=None, form=None, trainer=None, **options):
        super().__init__(system, form or "mat", **options)
        if self.form not in ("crops", "mat"):
            raise ValueError(f"expected --form crops or mat, got {self.form!r}")
        if trainer is not None and trainer not in TRAINERS:
            raise ValueError(f"expected --trainer in {', '.join(TRAINERS)}, got {trainer!r}")
        self.trainer = trainer if trainer is not None or self.form == "crops" else "6drepnet"
        self.needs_landmarks = self.uses_landmarks = self.form == "mat"
        if self.form == "crops":  # DirectMHP's full-range 6DRepNet data: COCO euler_angles, 256 x 256 crops
            self.system = "whenet"
            self.default_size = 256
            self.stretch = True

    @property
    def loader(self) -> str:
        """The trainer code that reads this export (``repo@commit file:lines``)."""
        if self.form == "crops":
            return LOADERS[("crops", None)] + (f"; range rule of --trainer {self.trainer}" if self.trainer else "")
        return LOADERS[("mat", self.trainer)]

    def label_reasons(self, angles):
        if self.trainer == "hopenet":
            bad = ((angles < -99.0) | (angles >= 99.0)).any(1)
            return np.where(bad, RULE_HOPENET, "").astype(object)
        if self.trainer == "6drepnet":
            return np.where(abs_over(angles, 99.0), RULE_6DREPNET, "").astype(object)
        return np.full(len(angles), "", dtype=object)

    def crop_boxes(self, rows, boxes, landmarks):
        if self.form != "mat":
            return boxes
        if landmarks is None or np.asarray(landmarks).ndim != 3 or np.asarray(landmarks).shape[1] == 0:
            raise HpeError(
                "--layout 6drepnet --form mat needs 2-D landmarks (lm0_x, lm0_y, ... or pt2d): 6DRepNet's and "
                "Hopenet's loaders crop each face from pt2d; the input has none: use --form crops"
            )
        t = landmark_boxes(landmarks)
        ml, mt, mr, mb = MAT_MARGINS
        return np.stack(
            [t[:, 0] - ml * t[:, 2], t[:, 1] - mt * t[:, 3], t[:, 2] * (1 + ml + mr), t[:, 3] * (1 + mt + mb)], axis=1
        )

    def finish(self, exported, final_root):
        notes = [f"read by {self.loader}"]
        if self.form == "crops":
            for split, part in exported.groupby("split", sort=True):
                ang = part[["pitch", "yaw", "roll"]].to_numpy(dtype=np.float64).tolist()
                lines = [f"{f} {p!r} {y!r} {r!r}\n" for f, (p, y, r) in zip(part["file"].tolist(), ang)]
                with open(self.root / f"files_{split}.txt", "w", encoding="utf-8", newline="") as fh:
                    fh.writelines(lines)
            return notes

        n_lm = landmark_count(exported.columns)
        for split, part in exported.groupby("split", sort=True):
            names = []
            lm = np.stack([part[[f"lm{i}_{a}" for i in range(n_lm)]].to_numpy(dtype=np.float64) for a in "xy"], -1)
            box = part[["crop_x0", "crop_y0", "crop_x1", "crop_y1"]].to_numpy(dtype=np.int64)
            size = part[["out_w", "out_h"]].to_numpy(dtype=np.int64)
            rad = np.deg2rad(part[["pitch", "yaw", "roll"]].to_numpy(dtype=np.float64))
            td = (
                part[["tdx", "tdy", "tdz", "scale"]].to_numpy(dtype=np.float64)
                if "tdx" in part
                else np.full((len(part), 4), np.nan)
            )
            heights = part["image_height"].to_numpy(dtype=np.float64)
            for k, f in enumerate(part["file"].tolist()):
                name = f[:-4]
                pts = points_to_crop(lm[k : k + 1], box[k : k + 1], tuple(size[k]))[0]
                pts = pts[np.isfinite(pts).all(1)]
                # tdx/tdy: the projection centre in the written image (tdy counts from the bottom, SPEC §8)
                sx = size[k, 0] / (box[k, 2] - box[k, 0])
                sy = size[k, 1] / (box[k, 3] - box[k, 1])
                row = heights[k] - 1 - td[k, 1]
                tdx = (td[k, 0] - box[k, 0] + 0.5) * sx - 0.5
                tdy = size[k, 1] - 1 - ((row - box[k, 1] + 0.5) * sy - 0.5)
                pose = np.array([[rad[k, 0], rad[k, 1], rad[k, 2], tdx, tdy, td[k, 2], td[k, 3]]])
                savemat_pinned(
                    self.split_dir(split) / f"{name}.mat", {"Pose_Para": pose, "pt2d": np.ascontiguousarray(pts.T)}
                )
                names.append(name + "\n")
            with open(self.split_dir(split) / "files.txt", "w", encoding="utf-8", newline="") as fh:
                fh.writelines(names)
        return notes


#: the 116-byte description of every ``.mat`` hpe writes: scipy's text with a fixed platform and creation time
#: (scipy/scipy@v1.17.1 ``scipy/io/matlab/_mio5.py:849-858``, ``MatFile5Writer.write_file_header``, writes
#: ``os.name`` and ``time.asctime()`` there, so two exports of the same data would differ in every file)
MAT_DESCRIPTION = b"MATLAB 5.0 MAT-file Platform: posix, Created on: Thu Jan  1 00:00:00 1970"


def savemat_pinned(path, mdict) -> None:
    """``scipy.io.savemat(path, mdict, do_compression=False)`` with a fixed header description.

    A level-5 MAT-file starts with a 128-byte header: 116 bytes of text, 8 of subsystem offset, the version and
    the endian mark. scipy writes the platform and the current time into the text; hpe writes
    :data:`MAT_DESCRIPTION` (null-padded, as scipy pads) instead, so the same export gives the same bytes on any
    machine and day. The readers (``scipy.io.loadmat``, MATLAB) do not interpret the text.
    """

    import scipy.io

    buf = io.BytesIO()
    scipy.io.savemat(buf, mdict, do_compression=False)
    data = bytearray(buf.getbuffer())
    if not data.startswith(b"MATLAB 5.0 MAT-file"):  # pragma: no cover - another scipy header format
        raise RuntimeError("scipy.io.savemat wrote an unexpected MAT-file header")
    data[:116] = MAT_DESCRIPTION.ljust(116, b"\0")
    with open(path, "wb") as fh:
        fh.write(data)
