"""``HPE_PLUGINS``: modules the CLI imports before it runs a command, so their registrations take effect.

A plug-in is one Python file (or an importable module) that registers a reader, an export layout, a protocol, a
decoder or a system through the public calls (see the "Extending hpe" page of the docs). ``HPE_PLUGINS`` lists
them, separated by the path separator (``:`` on POSIX): each item is a ``.py`` file path or a module name.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from pathlib import Path

from ..errors import HpeError

_LOADED: set = set()


def load_plugins(spec: str | None = None) -> list:
    """Import every plug-in ``spec`` (default: ``$HPE_PLUGINS``) names, once per process; returns their names."""
    spec = os.environ.get("HPE_PLUGINS", "") if spec is None else spec
    names = []
    for item in (s.strip() for s in spec.split(os.pathsep)):
        if not item or item in _LOADED:
            continue
        try:
            if item.endswith(".py"):
                path = Path(item)
                if not path.is_file():
                    raise HpeError(f"HPE_PLUGINS: {item}: expected a Python file, got no such file")
                name = f"hpe_plugin_{path.stem}"
                module_spec = importlib.util.spec_from_file_location(name, path)
                module = importlib.util.module_from_spec(module_spec)
                sys.modules[name] = module
                module_spec.loader.exec_module(module)
            else:
                importlib.import_module(item)
        except HpeError:
            raise
        except Exception as exc:  # the plug-in's own error: one line naming it
            raise HpeError(f"HPE_PLUGINS: {item}: cannot load it: {type(exc).__name__}: {exc}") from None
        _LOADED.add(item)
        names.append(item)
    return names
