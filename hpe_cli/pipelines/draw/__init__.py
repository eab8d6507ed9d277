"""``hpe draw``: head poses drawn on their images, and the pictures of the audit and evaluate pages.

One module per concept:

- :mod:`.options` -- :class:`DrawOptions`, the command's settings (built by the click command and the API);
- :mod:`.rows` -- reading a label table for drawing (:func:`read_rows`, from a
  :class:`~hpe_cli.io.label_source.LabelSource`), where each face sits, how rows are named, writing pictures;
- :mod:`.plan` -- which picture each row is drawn on, checked before anything is drawn, and the rejected rows;
- :mod:`.render` -- drawing the planned pictures (images or contact sheets);
- :mod:`.job` -- :func:`run_draw`, the command;
- :mod:`.errors` -- ``hpe evaluate -o`` output: ground truth and prediction on one face (:func:`draw_worst`,
  :func:`render_worst`);
- :mod:`.flagged` -- ``hpe audit --plots``: the flagged rows (:func:`flagged_pictures`);
- :mod:`.consistency` -- ``hpe audit --consistency --plots``: the worst suspects and their page.
"""

from __future__ import annotations

from .errors import WorstOptions, draw_worst, render_worst, run_draw_errors
from .flagged import flagged_pictures
from .job import run_draw
from .options import DrawOptions
from .rows import read_rows

__all__ = [
    "DrawOptions",
    "WorstOptions",
    "draw_worst",
    "flagged_pictures",
    "read_rows",
    "render_worst",
    "run_draw",
    "run_draw_errors",
]
