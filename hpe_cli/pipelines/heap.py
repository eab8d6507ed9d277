"""glibc's malloc thresholds for the row jobs: freed temporaries kept for the next batch instead of faulted in again.

glibc gives the free top of a heap back to the kernel once it exceeds ``M_TRIM_THRESHOLD`` and maps every block
above ``M_MMAP_THRESHOLD`` afresh (both adjust themselves upward as large blocks are freed, unless one of them was
set explicitly, e.g. by the ``MALLOC_TRIM_THRESHOLD_`` variable that Dask's nanny sets for its workers). A job
that allocates and frees the same half-MB numpy columns batch after batch then faults their pages in again every
time: hundreds of thousands of page faults and up to a second of system CPU at 10M rows. Raising both thresholds
(:manpage:`mallopt(3)`) keeps the memory for reuse; the peak is unchanged (each arena keeps at most what it held at
once) and no result depends on it. Other platforms and allocators are left alone. :func:`small_page_array` maps
the few large arrays a job keeps to its end without huge pages (their first touch is cheaper that way).
"""

from __future__ import annotations

import os
import sys

import numpy as np

from ..io.transaction import current

_DONE: set = set()

#: ``mallopt`` parameters (glibc's malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: ``madvise`` advice: fault a range's pages in, writable (Linux 5.14+; asm-generic/mman-common.h)
_MADV_POPULATE_WRITE = 23


def raise_malloc_thresholds(mmap_threshold: int = 32 << 20, trim_threshold: int = 128 << 20) -> bool:
    """Set glibc's mmap and trim thresholds (bytes) once per process; True when set by this call.

    Parameters
    ----------
    mmap_threshold : int
        Blocks below this many bytes come from the heap (default 32 MiB).
    trim_threshold : int
        Free memory at a heap's top kept up to this many bytes (default 128 MiB).
    """
    key = (mmap_threshold, trim_threshold)
    if key in _DONE or not sys.platform.startswith("linux"):
        return False
    _DONE.add(key)
    try:
        import ctypes  # lazy: only where glibc may be there

        libc = ctypes.CDLL(None)
        ok = libc.mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold)) and libc.mallopt(
            _M_TRIM_THRESHOLD, int(trim_threshold)
        )
    except (OSError, AttributeError):
        return False
    return bool(ok)


def keep_freed_memory() -> bool:
    """:func:`raise_malloc_thresholds` with its defaults, inside an ``hpe`` command only (a command's output
    transaction is open: a library caller's process is left alone), and unless the user set
    ``MALLOC_TRIM_THRESHOLD_`` or ``MALLOC_MMAP_THRESHOLD_`` (their settings win). True when set by this call."""
    if current() is None or "MALLOC_TRIM_THRESHOLD_" in os.environ or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    return raise_malloc_thresholds()


def small_page_array(n: int, dtype) -> np.ndarray:
    """An uninitialised ``(n,)`` array of ``dtype`` in anonymous memory mapped for it, without the transparent
    huge-page advice numpy gives its large arrays.

    Where huge pages are used only in regions that ask for them (``madvise`` mode, the default of many
    distributions), asking makes the first touch of each 2 MB compact memory first on a long-running machine: the
    two 80 MB hash arrays of a 10M-row audit cost 0.15 s more CPU that way than in 4 KB pages (measured, same
    run). The pages are returned when the array and its views are gone; the values are the same either way.
    """
    import mmap  # lazy: only for the few arrays that need it

    dt = np.dtype(dtype)
    if n <= 0:
        return np.empty(0, dtype=dt)
    return np.frombuffer(mmap.mmap(-1, n * dt.itemsize), dtype=dt, count=n)


def prefault(*arrays) -> None:
    """Fault the pages of :func:`small_page_array` arrays in on a thread of their own, 4 MB at a time, front to back
    (``MADV_POPULATE_WRITE``), while the caller goes on.

    The threads that then write to the arrays find their pages mapped instead of faulting each in (zeroing 80 MB
    costs about 30 ms of CPU here, on whichever thread first writes): on a machine with an idle core that work
    leaves the threads doing the job. No value depends on it; elsewhere (not Linux, a kernel before 5.14) it does
    nothing and the pages fault in as they are written.
    """
    if not sys.platform.startswith("linux"):
        return
    maps = [a.base.obj for a in arrays if isinstance(getattr(a, "base", None), memoryview)]
    if not maps:
        return

    def run():
        for m in maps:
            for off in range(0, len(m), 4 << 20):
                try:
                    m.madvise(_MADV_POPULATE_WRITE, off, min(4 << 20, len(m) - off))
                except (OSError, ValueError):  # an older kernel, or the array is gone
                    return

    import threading  # lazy: only the jobs that keep such arrays

    threading.Thread(target=run, name="hpe-prefault", daemon=True).start()
