"""Two ``run`` commands on one Dagster home: the second says in one line that it waits for
the first (its pid and start time) and runs once the first ends; a killed run leaves no
stale lock."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pwa_pipeline.orchestration.run_lock import LOCK_NAME, exclusive_run

ROOT = Path(__file__).resolve().parents[2]
HOLD = """
import sys, time
from pwa_pipeline.orchestration.run_lock import exclusive_run
with exclusive_run(sys.argv[1]):
    print("held", flush=True)
    time.sleep(600)
"""


def _environ(tmp_path: Path) -> dict[str, str]:
    environ = {**os.environ, "PWA_PIPELINE_HOME": str(tmp_path),
               "DAGSTER_HOME": str(tmp_path / "home"),
               "PWA_DATASETS": str(tmp_path / "datasets.json"),
               "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    environ.pop("MLFLOW_TRACKING_URI", None)
    return environ


def test_a_second_run_on_one_store_waits_for_the_first_and_a_killed_run_frees_it(tmp_path):
    home = tmp_path / "home"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(home)], env=_environ(tmp_path),
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        second = subprocess.Popen(
            [sys.executable, "-m", "pwa_pipeline", "run", "--partition", "hure_vasak|paper"],
            cwd=tmp_path, env=_environ(tmp_path), stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True)
        line = second.stderr.readline().strip()
        assert line.startswith(f"pwa-pipeline run: another run is using the Dagster home "
                               f"{home} (pid {holder.pid}, started ")
        assert line.endswith(": this run starts when it ends (Ctrl-C to stop waiting)")
        assert " UTC; lock file " in line
        time.sleep(2)
        assert second.poll() is None  # still waiting
        assert not (tmp_path / "mlflow.db").exists()  # nothing of its run started
    finally:
        holder.send_signal(signal.SIGKILL)  # killed: no clean-up of its own
        holder.wait(timeout=30)
    out, err = second.communicate(timeout=300)  # the lock went with the holder: it runs
    assert second.returncode == 0, out + err
    assert "Traceback" not in out + err and "hure_vasak|paper" in out
    assert (home / LOCK_NAME).exists()  # the file stays, its lock is free again
    with exclusive_run(home):
        pass


def test_the_lock_is_held_for_the_block_only(tmp_path):
    with exclusive_run(tmp_path) as path:
        with pytest.raises(ValueError, match=rf"pid {os.getpid()}, started "):
            with exclusive_run(tmp_path):
                pass
        assert path == tmp_path / LOCK_NAME
    with exclusive_run(tmp_path):  # released at the block's end
        pass
