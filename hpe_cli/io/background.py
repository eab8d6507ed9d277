"""A file written from a background thread, so the bytes of one batch go to the
kernel while the next batch is being formatted.

File writes release the GIL, so on a machine with a spare core the write of
batch *k* overlaps the formatting of batch *k + 1*. At most ``depth`` writes
and ``max_bytes`` bytes are queued, so memory stays bounded.
"""

from __future__ import annotations

import errno
import os
import shutil
from collections import deque
from concurrent.futures import ThreadPoolExecutor


class BackgroundFile:
    """Write ``bytes``-like objects to the binary file ``fh`` in order, on one thread.

    Parameters
    ----------
    fh : binary file object
        Written only by the thread; closed by :meth:`close`.
    depth : int
        Writes queued at most; :meth:`write` waits for the oldest beyond that.
    max_bytes : int
        Bytes queued at most (one write of any size is always let through).
        The thread needs the GIL to start and to end each write, and a long
        C call of the formatting thread (one ``orjson.dumps``) holds it for
        tens of milliseconds: a queue of only two writes makes the formatter
        wait for the disk (a third of a COCO run, measured), a deeper one
        rides over those delays.

    Notes
    -----
    An error raised by a write (``ENOSPC``, ``EFBIG``, ...) is raised again by
    the next :meth:`write` or by :meth:`close`. :meth:`abort` drops what is
    queued and waits only for the write under way.
    """

    def __init__(self, fh, depth: int = 8, max_bytes: int = 96 << 20):

        self.fh = fh
        self.depth = max(1, int(depth))
        self.max_bytes = int(max_bytes)
        self._queued = 0  # bytes in the queued writes
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="hpe-write")
        self._pending = deque()

    def _make_room(self, nbytes: int) -> None:
        while self._pending and (len(self._pending) >= self.depth or self._queued + nbytes > self.max_bytes):
            fut, n = self._pending.popleft()
            self._queued -= n
            fut.result()

    def write(self, data) -> None:
        n = memoryview(data).nbytes
        self._make_room(n)
        self._pending.append((self._pool.submit(self.fh.write, data), n))
        self._queued += n

    def copy_from(self, path) -> None:
        """Append the whole content of the file ``path`` (after the writes queued before), copied by the
        kernel (``os.copy_file_range``) where it can, else through a buffer. The file is opened here, so it
        may be removed as soon as this returns."""
        self._make_room(0)
        src = open(path, "rb")
        try:
            self._pending.append((self._pool.submit(_append_file, self.fh, src), 0))
        except BaseException:
            src.close()
            raise

    def flush(self) -> None:
        """Wait for every queued write (raising the first error)."""
        while self._pending:
            fut, n = self._pending.popleft()
            self._queued -= n
            fut.result()

    def close(self) -> None:
        """Finish every queued write, then close the file (errors are raised)."""
        try:
            self.flush()
        finally:
            self._pool.shutdown(wait=True)
            self.fh.close()

    def abort(self) -> None:
        """Drop the queued writes, wait for the one under way, close the file; never raises."""
        for fut, _ in self._pending:
            fut.cancel()
        self._pending.clear()
        self._queued = 0
        self._pool.shutdown(wait=True)
        try:
            self.fh.close()
        except Exception:  # the file is being discarded anyway
            pass


def _append_file(fh, src) -> None:

    with src:
        fh.flush()
        left = os.fstat(src.fileno()).st_size
        if hasattr(os, "copy_file_range"):
            try:
                while left > 0:
                    n = os.copy_file_range(src.fileno(), fh.fileno(), left)
                    if n == 0:
                        break
                    left -= n
            except OSError as exc:
                if exc.errno not in (errno.EXDEV, errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP):
                    raise
        fh.seek(0, os.SEEK_END)  # the buffered file learns where the kernel left the descriptor
        if left > 0:  # no kernel copy (or a short one): the rest through a buffer
            src.seek(os.fstat(src.fileno()).st_size - left)
            shutil.copyfileobj(src, fh, 1 << 22)
