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
    from ..io.transaction import run_committed

    if run_committed():  # the outputs are in place: nothing to undo, the run ends normally
        _note_complete(signum)
        return
    _fired = True
    exc = Interrupted(signum)
    from ..io.transaction import in_critical_section, request_stop

    request_stop(exc)  # if the exception below is swallowed (a __del__, a callback), nothing commits anyway
    _terminate_children()  # so a pool's shutdown does not wait for work nobody will use
    _arm_watchdog(signum)
    if in_critical_section(exc):  # raised when the file operation under way is recorded
        return
    raise exc


_noted = False


def _note_complete(signum, frame=None) -> None:
    """A signal after the run's outputs were committed: say the run is complete (once) and go on to exit 0."""
    global _noted
    if _noted:
        return
    _noted = True
    try:
        os.write(
            2,
            f"hpe: {signal.Signals(signum).name} received after the outputs were committed; "
            "the run is complete\n".encode(),
        )
    except OSError:
        pass


def _ignore_at_exit() -> None:
    for s in SIGNALS:
        try:
            signal.signal(s, signal.SIG_IGN)
        except (OSError, ValueError):
            pass


def _is_program() -> bool:
    """This process is the ``hpe`` command itself (not a test runner or a library calling the group)."""
    import sys

    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    return getattr(spec, "name", None) == "hpe_cli.__main__" or os.path.basename(sys.argv[0] or "") == "hpe"


#: seconds the orderly shutdown may take after a signal before the watchdog ends the process
WATCHDOG_SECONDS = 10.0
reported = False


def _arm_watchdog(signum: int) -> None:
    """If the orderly cleanup hangs (a pool's lock taken when the signal landed, a thread join at exit),
    remove the staged outputs, stop the workers and exit 128+signum anyway."""

    def force():
        from ..io import transaction

        txn = transaction.active_transaction()
        try:
            if txn is not None:
                txn.abort()
        finally:
            stop_children(timeout=1.0)
            if not reported:
                try:
                    os.write(2, f"Error: interrupted ({signal.Signals(signum).name})\n".encode())
                except OSError:
                    pass
            os._exit(128 + signum)

    global _watchdog
    t = threading.Timer(WATCHDOG_SECONDS, force)
    t.daemon = True
    t.start()
    _watchdog = t


_watchdog = None


def _late(exc) -> None:
    """A signal held back by the commit of the run's outputs, which then completed: the run is complete."""
    global _fired, _watchdog
    from ..io.transaction import request_stop

    if _watchdog is not None:
        _watchdog.cancel()
        _watchdog = None
    request_stop(None)
    _fired = False
    _note_complete(getattr(exc, "signum", signal.SIGTERM))


def fired():
    """The :class:`Interrupted` of the signal received during this run, or None."""
    from ..io.transaction import stop_requested

    return stop_requested()


def _terminate_children() -> None:
    """Kill worker processes at once (SIGKILL: one busy in C code would finish its write otherwise) and
    reap them, so nothing they write can appear after the run's cleanup."""
    import multiprocessing

    children = multiprocessing.active_children()
    for p in children:
        try:
            p.kill()
        except Exception:  # noqa: BLE001 - already gone
            pass
    _kill_forked()
    for p in children:
        try:
            p.join(1.0)
        except Exception:  # noqa: BLE001
            pass


def _kill_forked() -> None:
    """SIGKILL every direct child process of this one that multiprocessing does not know yet (a signal
    landing inside ``Process.start()`` between the fork and its bookkeeping), then reap it (Linux)."""
    import multiprocessing

    me = os.getpid()
    known = {p.pid for p in multiprocessing.active_children()}  # multiprocessing reaps these itself
    try:
        tasks = os.listdir(f"/proc/{me}/task")
    except OSError:
        return
    pids = set()
    for t in tasks:
        try:
            with open(f"/proc/{me}/task/{t}/children") as f:
                pids.update(int(x) for x in f.read().split())
        except (OSError, ValueError):
            pass
    pids -= known
    pids.discard(_tracker_pid())
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    for pid in pids:
        try:
            os.waitpid(pid, 0)
        except OSError:  # reaped by multiprocessing meanwhile, or not ours to wait for
            pass


def _tracker_pid():
    """multiprocessing's resource tracker: left running (it ends by itself when this process does); killed,
    it would be started again by the next process a pool spawns while shutting down, printing a ``KeyError``
    traceback for every semaphore its predecessor knew."""
    try:
        from multiprocessing import resource_tracker

        return resource_tracker._resource_tracker._pid
    except (ImportError, AttributeError):
        return None


@contextmanager
def handled():
    """Install the handlers for the duration of a run (main thread only; elsewhere a no-op)."""
    global _owner, _fired
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from ..io.transaction import on_late_signal, reset_run_state, run_committed

    previous = {s: signal.getsignal(s) for s in SIGNALS}
    _owner, _fired = os.getpid(), False
    reset_run_state()
    on_late_signal(_late)
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
        on_late_signal(None)
        sys.unraisablehook = unraisable
        if run_committed() and _is_program():
            # the run is complete: a signal while the process exits (threads joined, buffers flushed) must
            # neither kill it with a signal status nor be reported as an interruption
            # Python resets its handlers to the default action as it finalises: ignore them from then on
            import atexit

            previous = {s: _note_complete for s in previous}
            atexit.register(_ignore_at_exit)
        for s, h in previous.items():
            try:
                signal.signal(s, h if h is not None else signal.SIG_DFL)
            except (TypeError, ValueError):
                pass


def stop_children(timeout: float = 2.0) -> None:
    """Terminate every worker process this process started (multiprocessing and ProcessPoolExecutor)."""
    import multiprocessing

    _kill_forked()
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
