"""A 24-partition sweep on shared services and a dask cluster against the in-process command
line.

24 partitions: twelve registered data sets of the paper's simulated system (1,000 samples,
seeds 100–111) × the sets ``default`` and ``paper`` of a hyper-parameter file of its own.
Four arms, each ``python -m pwa_pipeline run`` over every key on fresh stores:

- ``in-process, local stores``: every step in the command's process, the Dagster instance
  and MLflow on sqlite, the asset store a local folder (the one-machine default);
- ``in-process, shared services``: the same on the services of a team (the Dagster instance
  on PostgreSQL, ``mlflow server`` on PostgreSQL with ``--serve-artifacts``, the asset store
  at a ``file://`` URL through fsspec); its difference to the first, per partition, is what
  the shared services cost;
- ``dask, 1 worker`` and ``dask, 2 workers``: ``--scheduler`` on a ``dask scheduler`` with
  one or two single-threaded ``dask worker`` processes, started cold for the arm, on the same
  shared services.

Reported: the command's wall time, the partitions' own seconds (the sum of what its summary
lines say, without the command's start-up and leaderboard), per partition, and the speed-up
against the first arm; how busy the machine was. All services run on this machine's loopback.

Writes results/distributed.json and results/distributed.md.
Usage: python -m benchmarks.distributed
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

from benchmarks._cluster import (
    HPARAMS,
    dask_cluster,
    mlflow_server,
    postgres_missing,
    postgres_server,
)
from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_json
from benchmarks._ui import free_port
from pwa_pipeline.datasets import make_hure_vasak
from pwa_pipeline.datasets.user import UserDataset
from pwa_pipeline.orchestration.registry import DatasetRegistry

N_DATASETS, N_SAMPLES = 12, 1000
SETS = ("default", "paper")
ARMS = ("in-process, local stores", "in-process, shared services", "dask, 1 worker",
        "dask, 2 workers")
#: A partition's summary line of ``run``: ``  <key>: … (<seconds> s)``.
SUMMARY = re.compile(r"^  (\S+\|\S+): .*\((\d+\.\d) s\)$", re.MULTILINE)


def data_files(folder: Path) -> tuple[dict[str, str], list[str]]:
    """The hyper-parameter file and registry of :data:`N_DATASETS` data sets; the
    environment naming them and every partition key."""
    (folder / "hparams.toml").write_text(HPARAMS)
    registry = DatasetRegistry(folder / "datasets.json")
    names = [f"sim{i:02d}" for i in range(N_DATASETS)]
    for i, name in enumerate(names):
        d = make_hure_vasak(n_samples=N_SAMPLES, seed=100 + i)
        pd.DataFrame({"u1": d.u_train[0][:, 0], "u2": d.u_train[0][:, 1], "y1": d.y_train[0][:, 0],
                      "y2": d.y_train[0][:, 1]}
                     ).to_csv(folder / f"{name}.csv", index=False)
        registry.add(UserDataset(name=name, path=str(folder / f"{name}.csv"), u=("u1", "u2"),
                                 y=("y1", "y2")))
    return ({"PWA_HPARAMS": str(folder / "hparams.toml"),
             "PWA_DATASETS": str(folder / "datasets.json")},
            [f"{n}|{s}" for n in names for s in SETS])


def sweep(keys: list[str], env: dict[str, str], scheduler: str = "") -> dict:
    """``run`` over ``keys`` with ``env``: its wall time and the partitions' own seconds."""
    args = [a for k in keys for a in ("--partition", k)]
    if scheduler:
        args += ["--scheduler", scheduler]
    with Timer() as timer:
        done = subprocess.run([sys.executable, "-m", "pwa_pipeline", "run", *args], env=env,
                              capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"run failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    seconds = {k: float(s) for k, s in SUMMARY.findall(done.stdout.split("Summary")[1])}
    assert sorted(seconds) == sorted(keys), seconds
    print(f"  {timer.seconds:.1f} s", flush=True)
    return {"wall_s": timer.seconds, "partition_s": sum(seconds.values()),
            "per_partition_s": seconds}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args(argv)
    if (missing := postgres_missing()) is not None:
        raise SystemExit(missing)
    base = {k: v for k, v in os.environ.items()
            if k not in ("MLFLOW_TRACKING_URI", "PWA_STORAGE", "PWA_DAGSTER_POSTGRES_URL",
                         "PWA_DASK_SCHEDULER")}
    folder = Path(tempfile.mkdtemp(prefix="pwa-distributed-"))
    results = {}
    load = MachineLoad()
    try:
        files, keys = data_files(folder)
        databases = tuple(f"{kind}{i}" for i in range(1, len(ARMS)) for kind in
                          ("dagster", "mlflow"))
        with postgres_server(databases) as postgres:
            for i, arm in enumerate(ARMS):
                home = folder / f"arm{i}"
                env = {**base, **files, "PWA_PIPELINE_HOME": str(home),
                       "DAGSTER_HOME": str(home / "dagster")}
                print(f"{arm}: {len(keys)} partitions", flush=True)
                home.mkdir()
                if i == 0:
                    results[arm] = sweep(keys, env)
                    continue
                env["PWA_DAGSTER_POSTGRES_URL"] = f"{postgres}/dagster{i}"
                env["PWA_STORAGE"] = (home / "store").as_uri()
                with mlflow_server(f"{postgres}/mlflow{i}", home / "artifacts", free_port(),
                                   home / "mlflow.log") as url:
                    env["MLFLOW_TRACKING_URI"] = url
                    if arm.startswith("in-process"):
                        results[arm] = sweep(keys, env)
                        continue
                    workers = int(arm.split(", ")[1].split()[0])
                    worker_env = {**files,
                                  "PWA_DAGSTER_POSTGRES_URL": env["PWA_DAGSTER_POSTGRES_URL"]}
                    with dask_cluster(workers, worker_env, home / "dask.log") as cluster:
                        results[arm] = sweep(keys, env, cluster.address)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    machine = load.summary()
    local, shared = results[ARMS[0]], results[ARMS[1]]
    overhead = (shared["partition_s"] - local["partition_s"]) / len(keys)
    summary = {"partitions": len(keys), "samples": N_SAMPLES, "machine_load": machine,
               "cpus": len(os.sched_getaffinity(0)),
               "shared_services_overhead_s_per_partition": overhead,
               "arms": {arm: {k: v for k, v in r.items() if k != "per_partition_s"}
                        for arm, r in results.items()}}
    print(summary)
    write_json({"summary": summary, "partitions": {a: r["per_partition_s"]
                                                   for a, r in results.items()}},
               "distributed")
    rows = "".join(
        f"| {arm} | {r['wall_s']:.1f} | {r['partition_s'] / len(keys):.2f} | "
        f"{local['wall_s'] / r['wall_s']:.2f}× |\n" for arm, r in results.items())
    md = [f"`python -m pwa_pipeline run` over {len(keys)} partitions ({N_DATASETS} registered "
          f"data sets of the simulated system, {N_SAMPLES:,} samples each, × the sets "
          f"{' and '.join(SETS)}), fresh stores in each arm, one run each; every service on "
          f"this machine's loopback; {describe_load(machine)}; {summary['cpus']} CPUs.\n",
          "| arm | wall s | s per partition (its run) | speed-up (wall) |\n"
          "|---|---|---|---|\n" + rows,
          f"The shared services (Dagster on PostgreSQL, `mlflow server` on PostgreSQL with "
          f"`--serve-artifacts`, the asset store through fsspec) cost {overhead:+.2f} s per "
          f"partition against the local stores, in process. On dask each step is a task: "
          f"the worker rebuilds the step's plan and opens the instance for it, so a "
          f"partition of seconds pays that per step; the partitions of one client run one "
          f"after the other (dagster-dask names tasks by job and step, see "
          f"`pwa_pipeline/orchestration/jobs.py`), each with the chain and the two "
          f"baselines side by side on the workers.\n"]
    (RESULTS / "distributed.md").write_text("\n".join(md))


if __name__ == "__main__":
    main()
