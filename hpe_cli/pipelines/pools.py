"""Where independent units of work run: this process, local worker processes, or Dask distributed.

:func:`unit_pool` gives an object with ``submit(fn, arg) -> future`` (futures
have ``result()`` and ``done()``): a :class:`concurrent.futures.ProcessPoolExecutor`
for ``workers > 1`` (the default engine), a Dask ``Client`` for a
``scheduler`` (the optional extra, see :mod:`.dask_runner`), or this process.
:func:`in_order` maps a function over items on such a pool with a bounded
number in flight and yields the results in input order, so a job can chain
stages (compute a unit, then format it) on one pool and still write its
output in order; :func:`run_in_order` does it on threads of its own for the
row jobs that write each result as it comes. No scheduling of our own: the engines schedule.
"""

from __future__ import annotations

import importlib
import os
import sys
import threading
import time
from collections import deque
from contextlib import contextmanager

from ..errors import HpeError


class _Inline:
    """``submit`` runs the function at once, in this process (one worker, no scheduler)."""

    workers = 1

    def submit(self, fn, arg):
        from concurrent.futures import Future  # lazy: start-up

        fut = Future()
        try:
            fut.set_result(fn(arg))
        except Exception as exc:  # a BaseException (a signal) propagates at once
            fut.set_exception(exc)
        return fut


class _Tracking:
    """Keeps the futures it submitted that may not be done yet (finished ones are dropped now and then)."""

    workers = 1

    def __init__(self):
        self.futures: list = []

    def _track(self, fut):
        self.futures.append(fut)
        if len(self.futures) > max(64, 4 * self.workers):
            self.futures = [f for f in self.futures if not f.done()]
        return fut


class _DaskPool(_Tracking):
    def __init__(self, client, workers: int):
        super().__init__()
        self.client = client
        try:
            threads = sum(client.nthreads().values())
        except Exception:  # an old or unusual client: fall back to what was asked
            threads = 0
        self.workers = max(int(workers), int(threads), 1)

    def submit(self, fn, arg):
        return self._track(self.client.submit(fn, arg, pure=False))

    def cancel(self) -> None:
        pending = [f for f in self.futures if not f.done()]
        if pending:
            self.client.cancel(pending)


def _import_all(names) -> None:

    for name in names:
        importlib.import_module(name)


def die_with_parent(parent: int) -> None:
    """Make this worker process end when its parent does, however the parent ends (``kill -9`` included).

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (the kernel kills the worker when the parent's thread that
    started it exits); everywhere, also a daemon thread that polls ``os.getppid()`` once a second and ends the
    process when the parent is gone (re-parented). A parent already gone when this runs ends it at once.
    """

    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:
        os._exit(1)

    def watch():

        while True:
            time.sleep(1.0)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="hpe-parent-watch", daemon=True).start()


def _worker_init(names, parent: int) -> None:
    """Initializer of every local worker: die with the parent, then import ``names``."""
    die_with_parent(parent)
    _import_all(names)


def mp_context():
    """``fork`` where the platform's default allows it (fast start, no re-import), else ``spawn``."""
    import multiprocessing as mp  # lazy: start-up (4 ms), only process pools need it

    return mp.get_context("spawn" if mp.get_start_method(allow_none=True) == "spawn" else "fork")


@contextmanager
def unit_pool(workers: int = 1, scheduler: str | None = None, warm=()):
    """A pool for unit functions (module-level, picklable by reference, returning small results).

    Parameters
    ----------
    workers : int
        Local worker processes (``> 1``: a process pool; ``1``: this process), or
        the size of a Dask ``LocalCluster`` with ``scheduler="local"``.
    scheduler : str, optional
        A Dask distributed scheduler address (``tcp://host:8786``) or ``"local"``.
    warm : iterable of str
        Modules every local worker imports as it starts. The workers are
        started at once (not at the first unit) and import these while this
        process goes on preparing the job, so the first units do not wait for
        them (pandas alone takes about 0.25 s to import).

    Notes
    -----
    On leaving, a process pool waits for the units under way; callers keep
    only a few in flight (:func:`in_order`), so an error or a signal stops the
    job after those few.
    """
    if scheduler is not None:
        from .dask_runner import dask_client  # lazy: start-up

        with dask_client(scheduler, workers) as client:
            pool = _DaskPool(client, workers)
            try:
                yield pool
            finally:
                pool.cancel()
    elif workers > 1:
        from concurrent.futures import ProcessPoolExecutor  # lazy: start-up

        with ProcessPoolExecutor(
            max_workers=workers, mp_context=mp_context(), initializer=_worker_init, initargs=(tuple(warm), os.getpid())
        ) as ex:
            ex.workers = workers
            for _ in range(workers):  # start every worker now (each runs the initializer, then this no-op)
                ex.submit(_import_all, ())
            yield _Local(ex, workers)
    else:
        yield _Inline()


class _Local:
    """A ``ProcessPoolExecutor`` whose futures turn a worker's death into one clear error."""

    def __init__(self, ex, workers: int):
        self.ex = ex
        self.workers = workers

    def submit(self, fn, arg):
        from concurrent.futures.process import BrokenProcessPool  # lazy: start-up

        try:
            return _Checked(self.ex.submit(fn, arg))
        except BrokenProcessPool:
            raise _died() from None


class _Checked:
    """A future whose ``result()`` raises one clear :class:`~hpe_cli.errors.HpeError` instead of
    ``BrokenProcessPool`` when a worker died."""

    __slots__ = ("fut",)

    def __init__(self, fut):
        self.fut = fut

    def result(self, timeout=None):
        from concurrent.futures.process import BrokenProcessPool  # lazy: start-up

        try:
            return self.fut.result(timeout)
        except BrokenProcessPool:
            raise _died() from None

    def done(self):
        return self.fut.done()

    def cancel(self):
        return self.fut.cancel()

    def cancelled(self):
        return self.fut.cancelled()


def _died():

    return HpeError(
        "a worker process died while computing a unit (killed, out of memory or crashed); "
        "nothing was written: run again (with --resume to keep the finished units)"
    )


class _Borrowed(_Tracking):
    """A started pool lent to one job (:func:`borrow`): it keeps the job's own units."""

    def __init__(self, pool):
        super().__init__()
        self.pool = pool
        self.workers = getattr(pool, "workers", 1)

    def submit(self, fn, arg):
        return self._track(self.pool.submit(fn, arg))


@contextmanager
def borrow(pool):
    """Lend a pool that is already running (started by the caller, for instance while the job is planned)
    to one job. On leaving, the job's units that have not started are cancelled and those under way are
    waited for, as leaving :func:`unit_pool` would; the pool itself goes on."""
    lent = _Borrowed(pool)
    try:
        yield lent
    finally:
        for fut in lent.futures:
            fut.cancel()
        for fut in lent.futures:
            if not fut.cancelled():
                try:
                    fut.result()
                except BaseException:  # the job's own error is already on its way
                    pass


def in_order(pool, fn, items, ahead: int | None = None):
    """Yield ``fn(item)`` for every item, computed on ``pool``, in input order.

    At most ``ahead`` (default: twice the pool's workers) are submitted
    beyond the one being waited for, so memory and the work lost to an error
    stay bounded.
    """

    ahead = max(1, int(ahead if ahead is not None else 2 * getattr(pool, "workers", 1)))
    pending: deque = deque()
    it = iter(items)
    try:
        for item in it:
            pending.append(pool.submit(fn, item))
            if len(pending) >= ahead:
                break
        while pending:
            res = pending.popleft().result()
            nxt = next(it, None)
            if nxt is not None:
                pending.append(pool.submit(fn, nxt))
            yield res
    finally:  # an error or an early close: the items not started yet are not run
        for fut in pending:
            fut.cancel()


def run_in_order(items, work, finish, threads: int) -> None:
    """``finish(*item, work(item[0]))`` for every tuple ``item``, in input order, while ``work`` runs on
    ``threads`` threads (:func:`in_order` on a thread pool of its own).

    At most ``threads + 1`` items are in flight, so memory stays flat: the pattern of the row jobs that read
    batches on this thread (``item[1:]`` rides along: line numbers, the reader's rejects), compute on the threads
    and write on this thread in input order.
    """
    from concurrent.futures import ThreadPoolExecutor  # lazy: start-up

    with ThreadPoolExecutor(threads) as pool:
        done = in_order(pool, lambda item: (item, work(item[0])), items, ahead=threads + 1)
        try:
            for item, result in done:
                finish(*item, result)
        finally:
            done.close()


#: the default thread count's cap: each thread keeps a chunk in flight, so memory grows with the count
MAX_DEFAULT_THREADS = 8


def default_threads(threads=None) -> int:
    """``threads`` when given (``--threads``), else one per core (``os.cpu_count()``), between 1 and
    :data:`MAX_DEFAULT_THREADS`."""

    return max(1, int(threads)) if threads else max(1, min(MAX_DEFAULT_THREADS, os.cpu_count() or 1))


@contextmanager
def library_threads(threads=None):
    """Limit the thread pools of OpenCV (``cv2.setNumThreads``) and pyarrow (``set_cpu_count``,
    ``set_io_thread_count``) to :func:`default_threads` ``(threads)`` for the run; yield that number.

    The previous settings are restored on exit, also on an error. For the commands whose row work runs on
    one Python thread (``--threads`` of biwi, infer) or on a few (draw, relabel-agora), so that ``--threads
    N`` bounds what the libraries start as well.
    """
    n = default_threads(threads)
    import cv2  # lazy: start-up (OpenCV is heavy; `hpe --help` and a small convert must not load it)
    import pyarrow as pa  # lazy: start-up (an `hpe infer --callable` child needs no pyarrow)

    before = (cv2.getNumThreads(), pa.cpu_count(), pa.io_thread_count())
    cv2.setNumThreads(n)
    pa.set_cpu_count(n)
    pa.set_io_thread_count(n)
    try:
        yield n
    finally:
        cv2.setNumThreads(before[0])
        pa.set_cpu_count(before[1])
        pa.set_io_thread_count(before[2])


__all__ = ["unit_pool", "borrow", "in_order", "run_in_order", "mp_context", "default_threads", "library_threads"]
