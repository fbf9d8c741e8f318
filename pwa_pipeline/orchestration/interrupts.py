"""Ctrl-C that reaches a run even where a library lets it pass.

Dagster stops a run on SIGINT by raising ``DagsterExecutionInterruptedError`` from its signal
handler, in whatever the main thread is running at that moment. A handler that raises inside
code which catches and drops the error (a finaliser, a library's clean-up, MLflow's logging)
leaves the run going to its end.
`interrupts_redelivered` notices every SIGINT at the C level, where no handler can
lose it, and sends it again while the run goes on. `interruptible` makes a run that
waits before its steps (for a busy dask scheduler) stop at once.
"""

import os
import select
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import dagster as dg

#: Seconds a run may take to end after a SIGINT before the signal is sent again (a step in
#: flight may need a few seconds to stop), and how often it is sent again at most.
GRACE, RESENDS = 5.0, 3


@contextmanager
def interrupts_redelivered(grace: float = GRACE, resends: int = RESENDS
                           ) -> Iterator[threading.Event]:
    """While the block runs, a SIGINT to this process that leaves it running ``grace``
    seconds later is sent again (at most ``resends`` times); the block's own handlers act on
    it as on the first. Yields an event set once a SIGINT came (for a block that ends by
    another error meanwhile, e.g. a storage that no longer answers, to be told apart).

    Every signal writes its number to a pipe (``signal.set_wakeup_fd``, at the C level,
    whatever the Python handler then does); a thread reads the pipe. The main thread blocks
    SIGINT meanwhile, so that the processes the block starts (which inherit the mask) are
    not stopped by a Ctrl-C to the process group; the reading thread receives it instead. In
    a thread other than the main thread (where signals cannot be observed) the block runs as
    it is.
    """
    came = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield came
        return
    read, write = os.pipe()
    os.set_blocking(write, False)
    previous = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
    done = threading.Event()

    def watch() -> None:
        sent = 0
        while not done.is_set():
            if not select.select([read], [], [], 0.2)[0]:
                continue
            if signal.SIGINT not in os.read(read, 512):
                continue
            came.set()
            if not done.wait(grace) and sent < resends:
                sent += 1
                os.kill(os.getpid(), signal.SIGINT)

    watcher = threading.Thread(target=watch, name="interrupts-redelivered", daemon=True)
    watcher.start()
    # SIGINT reaches the process through the watcher thread from now on (Python runs the
    # handlers in the main thread all the same); the processes the block starts inherit the
    # blocked signal, so a terminal's Ctrl-C, sent to the whole process group, does not make
    # Dagster's log-mirroring helpers print their own KeyboardInterrupt tracebacks
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield came
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        done.set()
        watcher.join()
        signal.set_wakeup_fd(previous)
        os.close(read)
        os.close(write)


@contextmanager
def interruptible(what: str) -> Iterator[None]:
    """While the block runs, SIGINT (Ctrl-C, the UI's "terminate") and a SIGTERM that
    Dagster handles as SIGINT raise ``DagsterExecutionInterruptedError`` at once, which
    Dagster records as the run's cancellation. Dagster itself only notes them during a run,
    and raises them where an executor waits for its steps, which a run waiting for the
    scheduler has not reached. ``what`` says what the block does, for the error's message.
    In a thread other than the main thread (where no handler can be set) the block runs as
    it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, frame):
        raise dg.DagsterExecutionInterruptedError(
            f"stopped while {what} ({signal.Signals(signum).name})")

    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    handled = [signal.SIGINT] + ([signal.SIGTERM] if previous[signal.SIGTERM]
                                 == previous[signal.SIGINT] else [])
    for sig in handled:
        signal.signal(sig, stop)
    try:
        yield
    finally:
        for sig in handled:
            signal.signal(sig, previous[sig])
