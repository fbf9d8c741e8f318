"""BLAS on one thread for the duration of a block (threadpoolctl, libraries looked up once)."""

from functools import cache

from threadpoolctl import ThreadpoolController


@cache
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


def single_threaded_blas():
    """Context manager: BLAS single-threaded inside (small or tall-thin products, or our own
    threads doing the parallel work); a fresh ``threadpool_limits`` scans the loaded
    libraries each time (~4 ms)."""
    return _controller().limit(limits=1, user_api="blas")
