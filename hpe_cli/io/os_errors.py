"""Short reasons for OS errors and printable file names, for one-line messages that name the user's path."""

from __future__ import annotations

import errno
import os
import re

from ..errors import HpeError

TEMP_PREFIX = ".hpe-"

_REASONS = {
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EROFS: "read-only file system",
    errno.ENOSPC: "disk full (no space left on device)",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large (file size limit reached)",
    errno.ENAMETOOLONG: "file name too long",
    errno.EISDIR: "is a folder",
    errno.ENOTDIR: "a parent of it is not a folder",
    errno.ENOENT: "no such file or folder",
    errno.EEXIST: "already exists",
    errno.EIO: "input/output error",
    errno.ELOOP: "too many levels of symbolic links",
    errno.EILSEQ: "file name is not valid in this file system's encoding",
}


def os_reason(exc: BaseException) -> str:
    """Short reason of an OS error (also pyarrow's, whose message carries ``[errno N]``)."""
    code = getattr(exc, "errno", None)
    if not code:
        m = re.search(r"errno[ =]?(\d+)", str(exc), re.IGNORECASE)
        code = int(m.group(1)) if m else None
    if code in _REASONS:
        return _REASONS[code]
    if code:
        return os.strerror(code).lower()
    short = re.search(r"(\d+) requested and (\d+) written", str(exc))
    if short:  # numpy's tofile on a short write (no errno): the device took only part of the bytes
        return f"disk full (the device took {short.group(2)} of {short.group(1)} bytes)"
    if isinstance(exc, UnicodeError):
        return "file name is not valid UTF-8"
    text = " ".join(str(exc).split())
    return re.sub(r"\S*" + re.escape(TEMP_PREFIX) + r"[0-9a-f]{8}\.tmp\S*", "", text)[:200] or type(exc).__name__


def printable(text) -> str:
    """``text`` with undecodable file-name bytes (surrogate escapes) shown as ``\\xNN``."""
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    text = str(text)
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def write_bytes(staged, data, shown) -> None:
    """Write ``data`` to the staged file ``staged``; an OS error (a full disk, a quota) is one line naming ``shown``,
    the path the user will see (not the temporary name), with the reason."""

    try:
        with open(staged, "wb") as fh:
            fh.write(memoryview(data).cast("B") if not isinstance(data, (bytes, bytearray)) else data)
    except OSError as exc:
        raise HpeError(f"{shown}: cannot write: {os_reason(exc)}") from None
