"""Reading a JSON file for the dataset readers (no table machinery: ``io`` builds on ``datasets``, not back)."""

from __future__ import annotations

from pathlib import Path

from ..errors import HpeError


def load_json(path: Path):
    """A JSON file's document (orjson); an unreadable file or invalid JSON is one HpeError naming the file."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise HpeError(f"{path}: cannot read: {exc.strerror or exc}") from None
    import orjson  # lazy: start-up

    try:
        return orjson.loads(data)
    except ValueError as exc:
        raise HpeError(f"{path}: not valid JSON ({' '.join(str(exc).split())[:160]})") from None
