"""User-facing errors: one line, no traceback, exit code 1 (2 for usage errors)."""


class HpeError(Exception):
    """A failure the user can act on. ``str(exc)`` is the whole message (one line)."""

    exit_code = 1


class UsageError(HpeError):
    """Options that contradict each other or the input (e.g. ``--system`` against the file's own): exit 2."""

    exit_code = 2
