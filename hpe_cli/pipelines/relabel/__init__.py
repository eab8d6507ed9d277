"""``hpe relabel-panoptic`` and ``hpe relabel-agora``: head-pose labels from 3-D face landmarks.

Both jobs share one method, :mod:`.core` (fit WHENet's reference head to each face, label
``A = E @ R_cam @ R_head``, box the head with a helmet, project the landmarks), and differ in what feeds it:

- Panoptic (:mod:`.panoptic`): sequences planned by :mod:`.plan` (calibration, cameras, frames), cut into
  units of frames that run here, on worker processes or on Dask (:mod:`.units`: part files, ``--resume``,
  ``--min-change``), counted by :mod:`.stats`;
- AGORA (:mod:`.agora`): one dataframe at a time.

:mod:`.options` holds each command's settings (:class:`RelabelPanopticOptions`, :class:`RelabelAgoraOptions`),
which the click modules and the Python API build alike.
"""

from __future__ import annotations

from .agora import run_relabel_agora
from .options import FORMATS, FormatSystemError, RelabelAgoraOptions, RelabelPanopticOptions
from .panoptic import PanopticRun, run_relabel_panoptic

__all__ = [
    "FORMATS",
    "FormatSystemError",
    "PanopticRun",
    "RelabelAgoraOptions",
    "RelabelPanopticOptions",
    "run_relabel_agora",
    "run_relabel_panoptic",
]
