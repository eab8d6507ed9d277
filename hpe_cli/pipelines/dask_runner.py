"""Run independent units of work on Dask distributed (optional extra ``dask``).

The same unit functions that local worker processes run are submitted to a
Dask cluster; each unit writes its own part files (so the cluster's workers
must see the same file system as the client, as a shared disk or a single
machine does) and returns only small counts. :func:`dask_client` gives the
client that :func:`hpe_cli.pipelines.pools.unit_pool` submits to; results are
taken in submission order (:func:`~hpe_cli.pipelines.pools.in_order`), so the
output does not depend on which worker ran what. ``address="local"`` starts a ``LocalCluster`` of ``workers`` single-threaded
processes (for testing and single machines). Dask is imported lazily.
"""

from __future__ import annotations

import os
import socket
import sys
from contextlib import contextmanager

from ..errors import HpeError
from ..io.transaction import os_reason

#: seconds to connect to a ``--scheduler`` address and to get its first bytes (a Dask scheduler speaks first)
CONNECT_SECONDS = 10.0


def probe(address: str, seconds: float | None = None) -> None:
    """Fail in seconds, with one clear line, on a ``--scheduler`` address that refuses connections, does not
    accept them, or accepts them and never answers (not a Dask scheduler, or a hung one): Dask's own
    ``Client(timeout=)`` does not bound the last case (its handshake read waits for ever).

    A Dask scheduler sends its handshake as soon as a connection is accepted
    (``distributed.comm.tcp``), so one byte within ``seconds`` shows something answers; ``tls://``
    addresses are only connected to (the client speaks first in TLS)."""

    seconds = CONNECT_SECONDS if seconds is None else seconds
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    if scheme not in ("tcp", "tls"):
        return
    host, _, port = rest.rstrip("/").rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit():
        raise HpeError(f"--scheduler {address}: expected tcp://HOST:PORT (or 'local')")
    try:
        conn = socket.create_connection((host, int(port)), timeout=seconds)
    except TimeoutError:
        raise HpeError(f"--scheduler {address}: no connection within {seconds:g} s") from None
    except socket.gaierror as exc:
        raise HpeError(f"--scheduler {address}: cannot resolve host {host!r} ({exc.strerror or exc})") from None
    except OSError as exc:
        raise HpeError(f"--scheduler {address}: cannot connect ({os_reason(exc)})") from None
    with conn:
        if scheme != "tcp":
            return
        conn.settimeout(seconds)
        try:
            data = conn.recv(1)
        except TimeoutError:
            raise HpeError(
                f"--scheduler {address}: accepts connections but sent nothing within {seconds:g} s "
                "(is it a Dask scheduler?)"
            ) from None
        except OSError as exc:
            raise HpeError(f"--scheduler {address}: cannot connect ({os_reason(exc)})") from None
        if not data:
            raise HpeError(f"--scheduler {address}: closed the connection without answering (is it a Dask scheduler?)")


def _quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker with its stderr on ``/dev/null``.

    The LocalCluster's worker processes share this process's tracker; when they are killed (a signal ends
    the run) it prints a ``KeyError`` traceback for every semaphore unregistered twice (CPython's
    ``resource_tracker.main``), on the stderr it inherited when it started. Started here first, it inherits
    ``/dev/null`` instead; the run's own messages still go to the real stderr."""

    try:
        from multiprocessing import resource_tracker
    except ImportError:  # not on this platform
        return
    if getattr(resource_tracker._resource_tracker, "_fd", None) is not None:
        return  # already running
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        return
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, 2)
        finally:
            os.close(null)
        resource_tracker.ensure_running()
    except OSError:
        pass
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _client(address: str, workers: int):
    if address != "local":
        probe(address)
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise HpeError("--scheduler needs Dask distributed: pip install 'hpe[dask]'") from None
    if address == "local":
        _quiet_resource_tracker()
        cluster = LocalCluster(
            n_workers=max(1, int(workers)),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=50,
        )
        return Client(cluster), cluster
    try:
        return Client(address, timeout=f"{CONNECT_SECONDS:g}s"), None
    except (OSError, TimeoutError) as exc:
        raise HpeError(f"--scheduler {address}: cannot connect ({exc})") from None


@contextmanager
def dask_client(address: str, workers: int = 1):
    """A Dask ``Client`` for ``address`` (``"local"``: a ``LocalCluster`` of ``workers`` single-threaded
    processes, closed on leaving)."""
    client, cluster = _client(address, workers)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


__all__ = ["dask_client"]
