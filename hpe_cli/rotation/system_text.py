"""Words and TOML text of :class:`~hpe_cli.rotation.system_def.RotationSystem` (no maths here)."""

from __future__ import annotations

import json

_CANONICAL_WORDS = {
    (0, 1): "subject's left (image right)",
    (0, -1): "subject's right (image left)",
    (1, 1): "up (towards the forehead)",
    (1, -1): "down (towards the chin)",
    (2, 1): "out of the face (towards the camera)",
    (2, -1): "into the head (away from the camera)",
}


def _esc(s: str) -> str:
    return s.replace("\\", "\\\\").replace('"', '\\"')


def _num(v) -> str:
    v = float(v)
    return str(int(v)) if v.is_integer() else repr(v)


def _fmt(v) -> str:
    try:
        return json.dumps(v)
    except (TypeError, ValueError):
        return repr(v)
