"""``hpe audit``: per-row checks, duplicates, the report, plots, a flagged table and ``--consistency``.

Modules: :mod:`.job` (the streaming job), :mod:`.consistency` (``--consistency``: landmarks, views, time),
:mod:`.groups` (its view and time checks), :mod:`.stream` (the same checks streamed by sequence and frame),
:mod:`.spill` (per-row evidence on disk), :mod:`.common` (the package's shared internals).
"""

from .consistency import Settings as ConsistencySettings
from .job import run_audit

__all__ = ["run_audit", "ConsistencySettings"]
