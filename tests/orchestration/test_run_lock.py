"""Two ``run`` commands on one Dagster home: the second is refused at once, in one line
naming the first (its pid and start time); a killed run leaves no stale lock."""

import os
import signal
import subprocess
import sys
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


def test_a_second_run_on_one_store_is_refused_in_one_line_and_a_killed_run_frees_it(tmp_path):
    home = tmp_path / "home"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(home)], env=_environ(tmp_path),
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        second = subprocess.run(
            [sys.executable, "-m", "pwa_pipeline", "run", "--partition", "hure_vasak|paper"],
            cwd=tmp_path, env=_environ(tmp_path), capture_output=True, text=True, timeout=300)
        assert second.returncode == 2, second.stdout + second.stderr
        assert "Traceback" not in second.stdout + second.stderr
        lines = second.stderr.strip().splitlines()
        assert len(lines) == 1, second.stderr
        assert lines[0].startswith(f"pwa-pipeline run: error: another run is using the "
                                   f"Dagster home {home} (pid {holder.pid}, started ")
        assert " UTC; lock file " in lines[0]
        assert not (tmp_path / "mlflow.db").exists()  # nothing of a run started
    finally:
        holder.send_signal(signal.SIGKILL)  # killed: no clean-up of its own
        holder.wait(timeout=30)
    assert (home / LOCK_NAME).exists()  # the file stays, its lock went with the process
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
