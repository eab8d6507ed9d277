"""SIGINT, SIGTERM and SIGHUP end a run cleanly: staged outputs removed, workers stopped, exit 128+signal.

:func:`handled` installs handlers that raise :class:`Interrupted` in the main
thread; the run's output transaction then aborts (its ``finally``), and the
group stops worker processes (:func:`stop_children`) and exits ``128 + N``.
Worker processes forked from this one inherit the handlers; there they
restore the default action and re-raise the signal, so a worker never runs
the parent's cleanup.
"""
from __future__ import annotations

import os
import signal
import threading
from contextlib import contextmanager

SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


class Interrupted(BaseException):
    """A signal asked the run to stop (a BaseException, like KeyboardInterrupt, so nothing swallows it)."""

    def __init__(self, signum: int):
        self.signum = signum
        self.name = signal.Signals(signum).name
        super().__init__(f"interrupted ({self.name})")


_owner = None
_fired = False


def _handler(signum, frame):
    global _fired
    if os.getpid() != _owner:  # a forked worker: behave as if no handler were installed
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    if _fired:  # cleanup already under way
        return
    _fired = True
    exc = Interrupted(signum)
    from ..io.transaction import in_critical_section, request_stop

    request_stop(exc)  # if the exception below is swallowed (a __del__, a callback), nothing commits anyway
    _terminate_children()  # so a pool's shutdown does not wait for work nobody will use
    if in_critical_section(exc):  # raised when the file operation under way is recorded
        return
    raise exc


def fired():
    """The :class:`Interrupted` of the signal received during this run, or None."""
    from ..io.transaction import stop_requested

    return stop_requested()


def _terminate_children() -> None:
    import multiprocessing

    for p in multiprocessing.active_children():
        try:
            p.terminate()
        except Exception:  # noqa: BLE001 - already gone
            pass


@contextmanager
def handled():
    """Install the handlers for the duration of a run (main thread only; elsewhere a no-op)."""
    global _owner, _fired
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from ..io.transaction import request_stop

    previous = {s: signal.getsignal(s) for s in SIGNALS}
    _owner, _fired = os.getpid(), False
    request_stop(None)
    for s in SIGNALS:
        signal.signal(s, _handler)
    import sys

    unraisable = sys.unraisablehook
    # an interrupt landing in a finaliser is reported by Python as "Exception ignored in ..." with a
    # traceback; the run is stopping anyway (request_stop above), so say nothing
    sys.unraisablehook = lambda u: None if isinstance(u.exc_value, Interrupted) else unraisable(u)
    try:
        yield
    finally:
        sys.unraisablehook = unraisable
        for s, h in previous.items():
            try:
                signal.signal(s, h if h is not None else signal.SIG_DFL)
            except (TypeError, ValueError):
                pass


def stop_children(timeout: float = 2.0) -> None:
    """Terminate every worker process this process started (multiprocessing and ProcessPoolExecutor)."""
    import multiprocessing

    children = multiprocessing.active_children()
    for p in children:
        try:
            p.terminate()
        except Exception:  # noqa: BLE001 - already gone
            pass
    for p in children:
        p.join(timeout)
        if p.is_alive():
            try:
                p.kill()
                p.join(timeout)
            except Exception:  # noqa: BLE001
                pass
