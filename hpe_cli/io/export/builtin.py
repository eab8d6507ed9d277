"""The built-in export layouts: importing this module registers them in :data:`hpe_cli.io.export.LAYOUTS`.

Each module registers its own class; the import order below is the order ``hpe export --help`` lists them in.
"""

from __future__ import annotations

# isort: off
from . import whenet  # noqa: F401
from . import sixdrepnet  # noqa: F401
from . import directmhp  # noqa: F401
from . import fsanet  # noqa: F401
from . import hf  # noqa: F401

# isort: on
