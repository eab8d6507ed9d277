"""User-facing errors: one line, no traceback, exit code 1 (2 for usage errors)."""


class HpeError(Exception):
    """A failure the user can act on. ``str(exc)`` is the whole message (one line)."""

    exit_code = 1


class UsageError(HpeError):
    """Options that contradict each other or the input (e.g. ``--system`` against the file's own): exit 2."""

    exit_code = 2


class RejectedAllError(HpeError):
    """Every row was rejected: the run fails (exit 1) and writes no main output, but the files in ``keep`` (the
    rejects file the user asked for, to see why) are still committed by the run's output transaction."""

    def __init__(self, message: str, keep=()):
        super().__init__(message)
        self.keep = [p for p in keep if p is not None]
