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
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import dagster as dg

#: Seconds a run may take to end after a SIGINT before the signal is sent again (a step in
#: flight may need a few seconds to stop), and how often it is sent again at most.
GRACE, RESENDS = 5.0, 3
#: What a Ctrl-C (or SIGINT) from outside says at once, and what a second one says as it
#: ends the process (`interrupts_redelivered`).
FIRST_INTERRUPT = ("interrupted: ending the run in flight (its steps stop, its MLflow run "
                   "is marked KILLED); Ctrl-C again stops at once")
SECOND_INTERRUPT = ("stopped at once (a second Ctrl-C): the run in flight may be left "
                    "started; `python -m pwa_pipeline doctor --repair` ends it")


@contextmanager
def interrupts_redelivered(grace: float = GRACE, resends: int = RESENDS,
                           say: Callable[[str], None] | None = None
                           ) -> Iterator[threading.Event]:
    """While the block runs, a SIGINT to this process that leaves it running ``grace``
    seconds later is sent again (at most ``resends`` times); the block's own handlers act on
    it as on the first. Yields an event set once a SIGINT came (for a block that ends by
    another error meanwhile, e.g. a storage that no longer answers, to be told apart).

    The first SIGINT from outside is said at once (`FIRST_INTERRUPT`, through ``say``;
    default: a line on stderr). A second one from outside ends the process at once with
    exit code 130, saying so (`SECOND_INTERRUPT`): a run whose storage no longer answers
    retries for about half a minute before any handler can act, and a user who presses
    Ctrl-C twice wants the command back. What it leaves started, `doctor` ends.

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

    say = say or (lambda line: print(line, file=sys.stderr, flush=True))
    own = [0]  # SIGINTs sent by the watcher itself and not yet read back

    def outside() -> int:
        """SIGINTs read from the pipe that did not come from the watcher."""
        if not select.select([read], [], [], 0.2)[0]:
            return 0
        count = os.read(read, 512).count(signal.SIGINT)
        mine = min(count, own[0])
        own[0] -= mine
        return count - mine

    def watch() -> None:
        sent = 0
        while not done.is_set():
            if not outside():
                continue
            came.set()
            say(FIRST_INTERRUPT)
            deadline = time.monotonic() + grace
            while not done.is_set():
                if outside():
                    say(SECOND_INTERRUPT)
                    os._exit(130)
                if time.monotonic() >= deadline and sent < resends:
                    sent += 1
                    own[0] += 1
                    os.kill(os.getpid(), signal.SIGINT)
                    deadline = time.monotonic() + grace

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
