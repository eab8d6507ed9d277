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

from contextlib import contextmanager

from ..errors import HpeError


def _client(address: str, workers: int):
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise HpeError("--scheduler needs Dask distributed: pip install 'hpe[dask]'") from None
    if address == "local":
        cluster = LocalCluster(n_workers=max(1, int(workers)), threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=40)
        return Client(cluster), cluster
    try:
        return Client(address, timeout="30s"), None
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
