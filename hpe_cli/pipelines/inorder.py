"""Overlapped read / compute / write: compute on a few threads, consume results in input order."""

from __future__ import annotations

from collections import deque


def in_order(items, work, finish, workers):
    """``finish(*item, future)`` in input order while ``work(item[0])`` runs on ``workers`` threads.

    At most ``workers + 1`` items are in flight, so memory stays flat.
    """
    from concurrent.futures import ThreadPoolExecutor  # lazy: start-up

    with ThreadPoolExecutor(workers) as pool:
        pending = deque()
        try:
            for item in items:
                pending.append((*item, pool.submit(work, item[0])))
                if len(pending) > workers:
                    finish(*pending.popleft())
            while pending:
                finish(*pending.popleft())
        finally:
            for *_, fut in pending:
                fut.cancel()
