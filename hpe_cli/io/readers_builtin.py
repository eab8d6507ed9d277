"""The built-in readers: importing this module registers them in :data:`hpe_cli.io.dataset_readers.READERS`.

The named label lists (``--input-format``) first, then the datasets: the order the readers are asked in.
"""

from __future__ import annotations

# isort: off
from . import columns  # noqa: F401  (whenet, celeba-pose, img2pose-biwi, opal23, coco)
from . import readers_datasets  # noqa: F401  (.mat, 300W-LP, DAD-3DHeads, BIWI)

# isort: on
