"""WHENet layout: head crops plus ``annotation.txt`` lines ``relative/path.jpg,yaw,pitch,roll``.

Followed: Ascend-Research/HeadPoseEstimation-WHENet's data preparation (``prepare_images.py``, as read in
:mod:`hpe_cli.io.whenet_txt`): one comma-separated line per head crop, the crop's path relative to the
dataset folder, then yaw, pitch, roll in degrees (``str(float)``), angles in the ``whenet`` system (300W-LP
matrix, yaw in (-180, 180], |pitch| and |roll| < 90). WHENet keeps a head only if |pitch| < 90 and |roll| < 90
in its primary solution; every row that rule removes is a reject.

Files: ``<split>/annotation.txt`` and ``<split>/<sequence>/<camera>_<person>_<frame>.jpg`` (crops); each
split folder is one WHENet dataset folder.
"""

from __future__ import annotations

import numpy as np

from ..whenet_txt import whenet_lines
from . import LAYOUTS
from .base import Layout

RULE = "WHENet rule: |pitch| >= 90 or |roll| >= 90 in the whenet primary solution"


@LAYOUTS.register()
class WhenetLayout(Layout):
    name = "whenet"
    system = "whenet"
    loader = (
        "Ascend-Research/HeadPoseEstimation-WHENet@a0d7bdfb prepare_images.py:160-165 (annotation.txt lines; "
        "the repository publishes no training loader)"
    )

    def label_reasons(self, angles):
        bad = (np.abs(angles[:, 0]) >= 90) | (np.abs(angles[:, 2]) >= 90)
        return np.where(bad, RULE, "").astype(object)

    def finish(self, exported, final_root):
        import pandas as pd

        for split, part in exported.groupby("split", sort=True):
            frame = pd.DataFrame(
                {
                    "image": part["file"].to_numpy(),
                    "pitch": part["pitch"].to_numpy(),
                    "yaw": part["yaw"].to_numpy(),
                    "roll": part["roll"].to_numpy(),
                }
            )
            path = self.split_dir(split) / "annotation.txt"
            with open(path, "w", encoding="utf-8", newline="") as fh:
                fh.writelines(whenet_lines(frame, path))
        return [f"format of {self.loader}"]
