"""Words and TOML text of :class:`~hpe_cli.rotation.system_def.RotationSystem` (no maths here)."""

from __future__ import annotations

import json

#: words for each canonical axis direction, keyed by (axis, sign)
CANONICAL_WORDS = {
    (0, 1): "subject's left (image right)",
    (0, -1): "subject's right (image left)",
    (1, 1): "up (towards the forehead)",
    (1, -1): "down (towards the chin)",
    (2, 1): "out of the face (towards the camera)",
    (2, -1): "into the head (away from the camera)",
}


def toml_escape(s: str) -> str:
    """``s`` escaped for a TOML basic (double-quoted) string."""
    return s.replace("\\", "\\\\").replace('"', '\\"')


def format_number(v) -> str:
    """A number as TOML text: an integer without ``.0``, else its shortest repr."""
    v = float(v)
    return str(int(v)) if v.is_integer() else repr(v)


def format_value(v) -> str:
    """A value as JSON text (repr when JSON cannot say it), for error messages."""
    try:
        return json.dumps(v)
    except (TypeError, ValueError):
        return repr(v)
