"""The README's first command, ``python -m pwa_pipeline run``, on fresh stores: wall time,
peak memory, and where the time goes.

Each repeat runs the command in a fresh process with ``PWA_PIPELINE_HOME`` set to a new
temporary directory (so the Dagster home, the asset store, the local-model cache and the
MLflow sqlite store are all created by the run) and ``MLFLOW_TRACKING_URI`` unset. Peak
memory is the largest sum of the resident memory of the command's processes, sampled every
0.1 s. The time of the first repeat is then split with the Dagster event log of its home:

- ``start``: process start to the first run's start (imports, definitions, the Dagster
  instance's creation);
- per partition: the run's wall time, the seconds of its steps (``STEP_START`` to
  ``STEP_SUCCESS``) by group — fitting (``*_model``, ``local_models``, ``clusters``,
  ``sub_models``, ``svm_regions``, ``output_error_refinement``), scoring (``*_scores``:
  evaluation, figure, MLflow logging), the rest — and, inside scoring, the MLflow logging
  with model registration (the ``mlflow_log_seconds`` of each ``*_scores`` asset; the first
  one of the process creates the MLflow store); what the run's wall time has beyond its
  steps is Dagster's own (events, storage, input loading between steps);
- ``leaderboard`` and ``end`` (last run to process exit).

Each repeat also counts the versions of each registered model in its MLflow store.

Writes results/first_command.json and results/first_command.md; the last line printed is a
summary.
Usage: python -m benchmarks.first_command [--repeats 3]
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import pandas as pd
import psutil

from benchmarks._common import RESULTS, MachineLoad, describe_load, write_json

ROOT = Path(__file__).resolve().parents[1]
FIT_STEPS = {"local_models", "clusters", "sub_models", "svm_regions", "output_error_refinement",
             "pwa_model", "linear_arx_model", "subspace_model"}


def one_run(home: Path) -> dict:
    """Run the command with its stores in ``home``; wall seconds, peak memory, the split."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("MLFLOW_TRACKING_URI", "DAGSTER_HOME", "PWA_DATASETS")}
    env.update(PWA_PIPELINE_HOME=str(home),
               PYTHONPATH=f"{ROOT}{os.pathsep}{env.get('PYTHONPATH', '')}".rstrip(os.pathsep))
    start = time.time()
    peak = 0
    with open(home / "output.txt", "w") as out:
        proc = subprocess.Popen([sys.executable, "-m", "pwa_pipeline", "run"], cwd=home,
                                env=env, stdout=out, stderr=subprocess.STDOUT)
        tree = psutil.Process(proc.pid)
        while proc.poll() is None:
            peak = max(peak, tree_rss(tree))
            time.sleep(0.1)
    wall = time.time() - start
    return {"wall_seconds": wall, "peak_gb": peak / 1024**3,
            "exit_code": proc.returncode, "model_versions": model_versions(home / "mlflow.db"),
            **split(home / ".dagster_home", start, start + wall)}


def model_versions(db: Path) -> dict[str, int]:
    """Versions of each registered model in the run's MLflow store (a model two partitions
    share is registered once)."""
    from mlflow.tracking import MlflowClient

    versions = MlflowClient(tracking_uri=f"sqlite:///{db}").search_model_versions()
    return dict(sorted(Counter(v.name for v in versions).items()))


def tree_rss(proc: psutil.Process) -> int:
    """Resident bytes of a process and its descendants (0 for those already gone)."""
    total = 0
    try:
        for p in [proc, *proc.children(recursive=True)]:
            try:
                total += p.memory_info().rss
            except psutil.NoSuchProcess:
                pass
    except psutil.NoSuchProcess:
        pass
    return total


def split(dagster_home: Path, start: float, end: float) -> dict:
    """Where the time of one command went, from its Dagster event log."""
    os.environ["DAGSTER_HOME"] = str(dagster_home)
    import dagster as dg

    instance = dg.DagsterInstance.get()
    partitions, leaderboard, first, last = [], None, None, None
    for run in sorted(instance.get_runs(), key=lambda r: instance.all_logs(r.run_id)[0].timestamp):
        logs = [r for r in instance.all_logs(run.run_id) if r.is_dagster_event]
        t_start, t_end = logs[0].timestamp, logs[-1].timestamp
        first = t_start if first is None else first
        last = t_end if last is None else max(last, t_end)
        steps, mlflow_log = {}, 0.0
        for r in logs:
            kind = r.dagster_event.event_type_value
            if kind == "STEP_START":
                steps[r.step_key] = -r.timestamp
            elif kind == "STEP_SUCCESS":
                steps[r.step_key] += r.timestamp
            elif kind == "ASSET_MATERIALIZATION":
                meta = r.dagster_event.event_specific_data.materialization.metadata
                if "mlflow_log_seconds" in meta:
                    mlflow_log += meta["mlflow_log_seconds"].value
        fit = sum(v for k, v in steps.items() if k in FIT_STEPS)
        score = sum(v for k, v in steps.items() if k.endswith("_scores"))
        row = {"partition": run.tags.get("dagster/partition"), "seconds": t_end - t_start,
               "started after the first": t_start - first,
               "fitting": fit, "scoring": score, "of which MLflow logging": mlflow_log,
               "other steps": sum(steps.values()) - fit - score,
               "Dagster between steps": t_end - t_start - sum(steps.values()),
               "local_models": steps.get("local_models"), "clusters": steps.get("clusters"),
               "sub_models": steps.get("sub_models"), "svm_regions": steps.get("svm_regions"),
               "subspace_model": steps.get("subspace_model")}
        if row["partition"] is None:
            leaderboard = t_end - t_start
        else:
            partitions.append(row)
    return {"start_seconds": first - start, "leaderboard_seconds": leaderboard,
            "end_seconds": end - last, "partitions": partitions}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    load = MachineLoad()
    runs: list[dict] = []
    for i in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            runs.append(one_run(Path(tmp)))
        print(f"repeat {i + 1}: {runs[-1]['wall_seconds']:.1f} s, peak "
              f"{runs[-1]['peak_gb']:.2f} GB, exit code {runs[-1]['exit_code']}", flush=True)
    machine = load.summary()
    cpus = len(os.sched_getaffinity(0))
    write_json({"machine_load": machine, "cpus": cpus, "repeats": args.repeats, "runs": runs},
               "first_command")
    wall = statistics.median(r["wall_seconds"] for r in runs)
    walls = pd.DataFrame([{
        "median seconds": wall, "runs": ", ".join(f"{r['wall_seconds']:.1f}" for r in runs),
        "peak GB": max(r["peak_gb"] for r in runs),
        "exit codes": ", ".join(str(r["exit_code"]) for r in runs),
        "registered versions": ", ".join(str(sum(r["model_versions"].values())) for r in runs)}])
    summary = (f"summary: python -m pwa_pipeline run on fresh stores {wall:.1f} s (median of "
               f"{args.repeats}; runs {walls['runs'].iloc[0]}), peak "
               f"{walls['peak GB'].iloc[0]:.2f} GB; load {machine['start']:.2f} -> "
               f"{machine['end']:.2f}, {machine['steal_share']:.0%} stolen, on {cpus} CPUs")
    first = runs[0]
    table = pd.DataFrame(first["partitions"]).set_index("partition")
    overview = pd.Series({"start (imports, definitions, instance)": first["start_seconds"],
                          **{f"partition {k}": v for k, v in table["seconds"].items()},
                          "leaderboard": first["leaderboard_seconds"],
                          "end": first["end_seconds"]}, name="seconds")
    md = [f"`python -m pwa_pipeline run` on fresh stores, {args.repeats} repeat(s); "
          f"{describe_load(machine)}; {cpus} CPUs. Peak memory: the largest sum over the "
          f"command's processes.\n", walls.to_markdown(index=False, floatfmt=".3g"), "",
          "## Where the first repeat's time went\n", overview.to_markdown(floatfmt=".3g"), "",
          "Per partition (seconds; scoring includes the MLflow logging with model "
          "registration):\n", table.to_markdown(floatfmt=".3g"), "",
          "Registered model versions (first repeat): " + ", ".join(
              f"{name} {n}" for name, n in first["model_versions"].items()) + "\n"]
    (RESULTS / "first_command.md").write_text("\n".join(md + [summary]) + "\n")
    print(summary)


if __name__ == "__main__":
    main()
