"""One `run` at a time per Dagster home: an exclusive lock on ``<home>/run.lock``.

Two ``python -m pwa_pipeline run`` at once on one store would compute every partition side
by side and log their MLflow runs interleaved; the second waits for the first to end (or,
asked not to wait, is refused at once), naming it (its pid and start time, which the holder
writes into the file). The lock is the operating system's
(``fcntl.flock``), held by the open file: it goes with the process, so a run that was killed
never leaves a stale lock, whatever the file still says. Without ``fcntl`` (Windows) no
lock is taken.
"""

import contextlib
import datetime as dt
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

#: The lock file's name in the Dagster home.
LOCK_NAME = "run.lock"


def _holder(fd: int) -> str:
    """What the holder wrote (``pid …, started …``), or that it has not written it yet."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        info = json.loads(os.read(fd, 4096).decode() or "{}")
        return f"pid {int(info['pid'])}, started {info['started']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "pid not yet written"


@contextlib.contextmanager
def exclusive_run(home: Path, on_wait: Callable[[str], None] | None = None) -> Iterator[Path]:
    """Hold ``<home>/run.lock`` for the ``with`` block; yield its path.

    Parameters
    ----------
    home : Path
    on_wait : callable, optional
        Told, in one line naming the run that holds the lock, that this one waits for it
        (until it ends; Ctrl-C stops the wait). None: refused at once instead.

    Raises
    ------
    ValueError
        Without ``on_wait``, in one line naming the run that holds it (pid and start
        time), when another process holds it.
    """
    home = Path(home)
    path = home / LOCK_NAME
    if fcntl is None:  # pragma: no cover - not POSIX
        yield path
        return
    home.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)  # not inherited by child processes
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = (f"another run is using the Dagster home {home} ({_holder(fd)}; lock "
                      f"file {path})")
            if on_wait is None:
                raise ValueError(f"{holder}: wait for it to end or stop it, then run "
                                 f"again") from None
            on_wait(f"{holder}: this run starts when it ends (Ctrl-C to stop waiting)")
            fcntl.flock(fd, fcntl.LOCK_EX)
        started = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps({"pid": os.getpid(), "started": started}).encode(), 0)
        yield path
    finally:
        os.close(fd)  # releases the lock
