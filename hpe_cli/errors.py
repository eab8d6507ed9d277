"""User-facing errors: one line, no traceback, exit code 1."""


class HpeError(Exception):
    """A failure the user can act on. ``str(exc)`` is the whole message (one line)."""

    exit_code = 1
