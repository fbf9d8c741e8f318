"""The command line's compute logs: captured in Dagster's files, mirrored by a thread."""

import os
import select
import subprocess
import sys
import textwrap
import threading

from pwa_pipeline.orchestration.compute_logs import _copy

RUN = textwrap.dedent('''
    import subprocess
    import dagster as dg
    from pwa_pipeline.orchestration.instance import prepare_instance

    started = []
    real = subprocess.Popen.__init__
    subprocess.Popen.__init__ = lambda self, args, *a, **k: (
        started.append(args), real(self, args, *a, **k))[1]

    @dg.asset
    def loud():
        print("printed by the step")
        print("x" * 300_000)
        print("the step's last line", flush=True)

    instance = prepare_instance()
    result = dg.materialize([loud], instance=instance)
    print("manager", type(instance.compute_log_manager).__name__, "success", result.success,
          "processes started", len(started))
''')


def test_a_run_is_captured_in_dagsters_files_and_mirrored_whole_without_processes(tmp_path):
    """What a step prints reaches the run's stdout file (the UI's view) and, copied to its end,
    the terminal (here a pipe); Dagster's log lines the stderr file and the terminal's
    stderr; no process is started for it (Dagster's class starts four a run)."""
    home = tmp_path / "home"
    env = {**os.environ, "DAGSTER_HOME": str(home)}
    done = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == (
        "manager ThreadMirroredComputeLogManager success True processes started 0")
    step = ["printed by the step", "x" * 300_000, "the step's last line"]
    assert done.stdout.splitlines()[:3] == step  # mirrored, whole, in order
    (out,) = (home / "storage").rglob("*.out")
    (err,) = (home / "storage").rglob("*.err")
    assert out.read_text().splitlines() == step
    assert "Finished execution of step" in err.read_text()
    assert err.read_text() in done.stderr  # Dagster's log lines, mirrored
    assert list((home / "storage").rglob("*.complete"))


def _received(fd: int, size: int) -> bytes:
    """What the pipe ``fd`` gives until ``size`` bytes or 5 s without any."""
    received = b""
    while len(received) < size and select.select([fd], [], [], 5)[0]:
        received += os.read(fd, 1 << 16)
    return received


def test_the_mirror_copies_to_the_end_and_stops_when_the_terminal_is_gone(tmp_path,
                                                                         monkeypatch):
    raised = []
    monkeypatch.setattr(threading, "excepthook", raised.append)
    path = tmp_path / "captured.out"
    path.write_bytes(b"a" * 200_000)  # more than a pipe holds
    done = threading.Event()
    done.set()  # the capture has ended: the copy reads to the end, then stops
    read, write = os.pipe()
    copier = threading.Thread(target=_copy, args=(str(path), write, done))
    copier.start()
    assert _received(read, 200_000) == b"a" * 200_000
    copier.join(timeout=10)
    assert not copier.is_alive()
    os.close(read)  # the terminal is gone: writing fails, and the copy ends quietly
    copier = threading.Thread(target=_copy, args=(str(path), write, done))
    copier.start()
    copier.join(timeout=10)
    assert not copier.is_alive() and raised == []
    os.close(write)
