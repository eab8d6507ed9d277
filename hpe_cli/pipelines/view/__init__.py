"""``hpe view``: a browsable offline page of every row of a label table (and of a second one beside it).

- :mod:`.options` -- :class:`ViewOptions`, the command's settings (built by the click command and the API);
- :mod:`.tables` -- LABELS and OTHER read whole, each in its own system, and paired by key;
- :mod:`.thumbs` -- the thumbnails and reduced frames, made in parallel and cached by content;
- :mod:`.job` -- :func:`run_view`, the command (the page itself is :mod:`hpe_cli.report.view_page`).
"""

from __future__ import annotations

from .job import also_angles, run_view
from .options import ViewOptions
from .tables import Table, read_table

__all__ = ["Table", "ViewOptions", "also_angles", "read_table", "run_view"]
