"""``hpe audit``: per-row checks, duplicates, the report, plots, a flagged table and ``--consistency``.

Modules: :mod:`.job` (the streaming job and its steps), :mod:`.options` (:class:`AuditOptions`), :mod:`.batches` (the
labels read and checked batch by batch), :mod:`.duplicates` (row hashes), :mod:`.flagged` (``-o``), :mod:`.consistency` (``--consistency``: landmarks, views, time),
:mod:`.groups` (its view and time checks), :mod:`.stream` (the same checks streamed by sequence and frame),
:mod:`.spill` (per-row evidence on disk), :mod:`.common` (the package's shared internals).
"""

from .job import run_audit
from .options import AuditOptions
from .options import Settings as ConsistencySettings

__all__ = ["run_audit", "AuditOptions", "ConsistencySettings"]
