"""``hpe augment``: rotate, mirror, crop or resize a labelled dataset (labels, landmarks, boxes, images).

The job, one module per concept:

- :mod:`.options` -- :class:`AugmentOptions`, the run's settings, validated once (built by the command line and
  the Python API alike);
- :mod:`.batches` -- the checks of the input's columns and, per batch on a worker thread, the labels, sizes,
  landmarks, boxes and ``tdx, tdy`` moved (:class:`~.batches.BatchPlan`);
- :mod:`.images` -- each row's picture found and sized once, warped into the staged ``--out-images`` folder,
  and a ``.mat`` folder's ``.mat`` files written back;
- :mod:`.job` -- :func:`run_augment`: read, transform and write in input order, with the rejects.
"""

from __future__ import annotations

from .batches import row_sizes
from .images import ImageJob, RowImages, output_name
from .job import run_augment
from .options import AGREE_TOL, IMAGE_COLUMNS, OPS, AugmentOptions, describe_op, for_input

__all__ = [
    "AGREE_TOL",
    "IMAGE_COLUMNS",
    "OPS",
    "AugmentOptions",
    "ImageJob",
    "RowImages",
    "describe_op",
    "for_input",
    "output_name",
    "row_sizes",
    "run_augment",
]
