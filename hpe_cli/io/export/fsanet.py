"""FSA-Net layout: one ``<split>.npz`` per split with ``image`` (N x S x S x 3 uint8) and ``pose`` (N x 3).

Followed: shamangary/FSA-Net@4361d0e4 ``data/type1/TYY_create_db_type1.py:117`` (the writer its training reads):
``np.savez(output, image=np.array(out_imgs), pose=np.array(out_poses), img_size=img_size)``, images read with
``cv2.imread`` (so **BGR**) and resized to ``img_size`` x ``img_size`` (64 by default), ``pose`` rows
``[yaw, pitch, roll]`` in degrees from ``Pose_Para`` (the ``300w_lp`` system, |yaw| <= 90). Its training
scripts load the arrays back with ``np.load(path)['image']`` / ``['pose']``
(``training_and_testing/FSANET_fine_train.py:25-27``, ``load_data_npz``) and keep only samples whose three angles
are within [-99, 99] (``:78-87``); labels outside are rejects here. thohemp/6DRepNet@464b2ba5
``sixdrepnet/datasets.py:177-228`` (``BIWI``) reads the same ``.npz`` (``pose`` = yaw, pitch, roll degrees,
``get_R(pitch, yaw, roll)``).

The crops are streamed to a raw temporary file and the ``.npz`` (a stored zip of ``.npy`` members, as
``np.savez`` writes) is assembled member by member, so memory stays flat.
"""

from __future__ import annotations

import zipfile

import numpy as np

from . import LAYOUTS
from .base import Layout, abs_over

RULE_99 = "outside ±99° (FSA-Net's FSANET_fine_train.py keeps [-99, 99])"


@LAYOUTS.register()
class FSANetLayout(Layout):
    name = "fsanet"
    system = "300w_lp"
    loader = (
        "shamangary/FSA-Net@4361d0e4 training_and_testing/FSANET_fine_train.py:25-27,78-92 (load_data_npz, "
        "the [-99, 99] filter); thohemp/6DRepNet@464b2ba5 sixdrepnet/datasets.py:177-228 (BIWI)"
    )
    pixels = "array"
    default_size = 64
    default_square = True

    def label_reasons(self, angles):
        return np.where(abs_over(angles, 99.0), RULE_99, "").astype(object)

    def open(self, root, splits):
        super().open(root, splits)
        self._raw = {}
        self._count = {}
        self._shape = None

    def add_pixels(self, split, rows, payloads):
        fh = self._raw.get(split)
        if fh is None:
            fh = self._raw[split] = open(self.root / f".{split}.image.raw", "wb")
            self._count[split] = 0
        for a in payloads:
            if self._shape is None:
                self._shape = a.shape
            fh.write(np.ascontiguousarray(a, dtype=np.uint8).tobytes())
        self._count[split] += len(payloads)

    def abort(self):
        for fh in getattr(self, "_raw", {}).values():
            fh.close()

    def finish(self, exported, final_root):
        for fh in self._raw.values():
            fh.close()
        for split, part in exported.groupby("split", sort=True):
            n = len(part)
            if n != self._count.get(split, 0):
                raise RuntimeError(f"fsanet: {split}: {n} rows but {self._count.get(split, 0)} crops")
            pose = part[["yaw", "pitch", "roll"]].to_numpy(dtype=np.float64)
            shape = (n,) + tuple(self._shape)
            raw = self.root / f".{split}.image.raw"
            with zipfile.ZipFile(self.root / f"{split}.npz", "w", compression=zipfile.ZIP_STORED, allowZip64=True) as z:
                with z.open("image.npy", "w", force_zip64=True) as out:
                    np.lib.format.write_array_header_1_0(
                        out,
                        {
                            "descr": np.lib.format.dtype_to_descr(np.dtype(np.uint8)),
                            "fortran_order": False,
                            "shape": shape,
                        },
                    )
                    with open(raw, "rb") as src:
                        while True:
                            chunk = src.read(1 << 22)
                            if not chunk:
                                break
                            out.write(chunk)
                with z.open("pose.npy", "w", force_zip64=True) as out:
                    np.lib.format.write_array(out, pose)
                with z.open("img_size.npy", "w") as out:
                    np.lib.format.write_array(out, np.asarray(int(self._shape[0])))
            raw.unlink()
        return [f"read by {self.loader}"]
