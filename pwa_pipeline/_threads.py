"""Work spread over threads, dropped at once when it is interrupted."""

from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor


def map_in_threads(pool: ThreadPoolExecutor, fn: Callable, items: Iterable) -> list:
    """``list(pool.map(fn, items))``, except that when waiting is interrupted (Ctrl-C raises
    KeyboardInterrupt in the waiting thread) or a task raises, the tasks not yet started
    are cancelled: leaving the pool then waits for the tasks running (a block each), not
    for every task queued (a whole neighbour search or local solve on a long record)."""
    futures = [pool.submit(fn, item) for item in items]
    try:
        return [future.result() for future in futures]
    except BaseException:
        for future in futures:
            future.cancel()
        raise
