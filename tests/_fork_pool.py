"""A fork pool for tests that run processes at once."""

import contextlib
import multiprocessing


@contextlib.contextmanager
def fork_pool(processes: int):
    """A fork pool ended by close + join: ``Pool.__exit__`` terminates its workers by SIGTERM,
    which pytest-xdist's workers ignore, and a worker blocked on the task queue's lock (held by
    the terminating pool) then never ends."""
    pool = multiprocessing.get_context("fork").Pool(processes)
    try:
        yield pool
    finally:
        pool.close()
        pool.join()
