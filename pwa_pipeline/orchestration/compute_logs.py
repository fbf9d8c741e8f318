"""The command line's Dagster compute logs: Dagster's local files, mirrored by a thread.

Dagster's :class:`~dagster._core.storage.local_compute_log_manager.LocalComputeLogManager`
(the default of a ``$DAGSTER_HOME``) captures a run's stdout and stderr (what the steps
print, Dagster's console log) in files under ``<home>/storage``, which the UI shows in a
run's *stdout* and *stderr* views, and mirrors them to where they went before (the
terminal): for each of the two streams it starts a ``tail -F`` process that copies the file
there, and a Python process that ends that ``tail`` if the run's process dies; at the end of
each run it stops the four processes and waits for them. :class:`ThreadMirroredComputeLogManager`
captures into the same files the same way (the stream's file descriptor pointed at its file)
and mirrors each file with a thread of the run's process instead: no process is started,
none can outlive the run's process, and the mirror has copied the whole file when the
capture ends (a ``tail`` stopped at once may not have: Dagster's
``DAGSTER_COMPUTE_LOG_TAIL_WAIT_AFTER_FINISH``). Where the files are and how the UI reads them
is Dagster's class. Measured by ``benchmarks/event_log.py``, whose pooled arms and floor run
on a home with this class.
"""

import os
import sys
import threading
from collections.abc import Generator, Sequence
from contextlib import contextmanager
from typing import IO

from dagster._core.execution.compute_logs import (
    redirect_to_file,
    should_disable_io_stream_redirect,
)
from dagster._core.storage.compute_log_manager import CapturedLogContext, ComputeIOType
from dagster._core.storage.local_compute_log_manager import (
    IO_TYPE_EXTENSION,
    LocalComputeLogManager,
)
from dagster._utils import ensure_file, touch_file

#: Seconds the mirror waits before it looks at a file again when it has copied all of it.
POLL_SECONDS = 0.05


class ThreadMirroredComputeLogManager(LocalComputeLogManager):
    """:class:`LocalComputeLogManager` that mirrors the captured files with a thread of the
    run's process rather than ``tail`` processes; its ``dagster.yaml`` configuration is the
    same (``base_dir``, ``polling_timeout``)."""

    @classmethod
    def from_config_value(cls, inst_data, config_value) -> "ThreadMirroredComputeLogManager":
        return cls(inst_data=inst_data, **config_value)

    @contextmanager
    def capture_logs(self, log_key: Sequence[str]) -> Generator[CapturedLogContext, None, None]:
        """Capture stdout and stderr in the files of ``log_key`` as Dagster's class does,
        each mirrored by :func:`_mirrored`; then mark the capture complete."""
        out = self.get_captured_local_path(log_key, IO_TYPE_EXTENSION[ComputeIOType.STDOUT])
        err = self.get_captured_local_path(log_key, IO_TYPE_EXTENSION[ComputeIOType.STDERR])
        with _mirrored(sys.stdout, out), _mirrored(sys.stderr, err):
            yield CapturedLogContext(log_key)
        touch_file(self.complete_artifact_path(log_key))


@contextmanager
def _mirrored(stream: IO, path: str) -> Generator[None, None, None]:
    """While the context lasts, ``stream``'s file descriptor writes to the end of the file
    ``path`` (Dagster's ``redirect_to_file``), and a thread copies the file, from its start,
    to where the descriptor wrote before; at the end the thread copies the rest and stops.
    A stream without a file descriptor (or on Windows without legacy stdio) is not captured,
    as in Dagster's class."""
    ensure_file(path)
    fd = _fileno(stream)
    if fd is None or should_disable_io_stream_redirect():
        yield
        return
    before = os.dup(fd)
    done = threading.Event()
    mirror = threading.Thread(target=_copy, args=(path, before, done), daemon=True,
                              name=f"compute-log mirror of {os.path.basename(path)}")
    mirror.start()
    try:
        with redirect_to_file(stream, path):
            yield
    finally:
        done.set()  # the file is complete (redirect_to_file flushed and closed it)
        mirror.join()
        os.close(before)


def _copy(path: str, fd: int, done: threading.Event) -> None:
    """Copy the file ``path`` to ``fd`` as it grows, until ``done`` is set and the file is
    copied to its end; a ``fd`` that can no longer be written (a closed terminal or pipe)
    ends the copy, not the capture."""
    with open(path, "rb") as source:
        try:
            while True:
                finished = done.is_set()  # looked at before reading: then nothing follows
                data = source.read(1 << 16)
                if data:
                    view = memoryview(data)
                    while view:
                        view = view[os.write(fd, view):]
                elif finished:
                    return
                else:
                    done.wait(POLL_SECONDS)
        except OSError:
            return


def _fileno(stream: IO) -> int | None:
    """``stream``'s file descriptor; None if it has none (e.g. a test runner's buffer)."""
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is an OSError
        return None
    return fd if isinstance(fd, int) else None
