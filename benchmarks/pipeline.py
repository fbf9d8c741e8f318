"""Pipeline cost: materialising the default partitions, and what the local-model cache saves.

1. Time to materialise every asset of each default partition (hure_vasak and kuka_robot with
   the 'paper' and 'default' sets), in-process with dg.materialize, fresh stores.
2. A sweep of 12 hyper-parameter sets on the simulated system that differ only in ε and MinPts
   (paper setting, n_rho = 18): every asset of every set, once with the local-model cache and
   once without; the saving is the difference (medians of the local_models step reported too).
   A set whose ε / MinPts leave DBSCAN without a cluster fails at `clusters` (as it should)
   and is timed all the same. The sweep's sets are written to a temporary hyper-parameter
   file that the pipeline reads through PWA_HPARAMS, so this part runs in a subprocess.

Writes results/pipeline.json and results/pipeline.md. Usage: python benchmarks/pipeline.py
"""

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks._common import RESULTS, Timer, write_json  # noqa: E402

EPS = (0.1, 0.15, 0.2, 0.3)
MIN_PTS = (10, 15, 20)


def _resources(tmp: Path, cache: bool):
    from pwa_pipeline.pipeline.resources import MLflowTracker, PipelineConfig
    from pwa_pipeline.pipeline.storage import PartitionedFileIOManager

    return {"io_manager": PartitionedFileIOManager(base_dir=str(tmp / "storage")),
            "config": PipelineConfig(cache_dir=str(tmp / "cache"), cache_local_models=cache),
            "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{tmp / 'mlflow.db'}")}


def _materialise(keys, tmp: Path, cache: bool) -> list[dict]:
    import dagster as dg

    from pwa_pipeline.pipeline.assets import ASSETS

    resources = _resources(tmp, cache)
    instance = dg.DagsterInstance.ephemeral()
    quiet = {"loggers": {"console": {"config": {"log_level": "ERROR"}}}}
    rows = []
    for key in keys:
        with Timer() as t:
            result = dg.materialize(ASSETS, partition_key=key, resources=resources,
                                    instance=instance, run_config=quiet, raise_on_error=False)
        local = result.asset_materializations_for_node("local_models")[0].metadata
        rows.append({"partition": key, "seconds": t.seconds, "success": result.success,
                     "local_models_seconds": local["seconds"].value,
                     "from_cache": local["from_cache"].value})
    return rows


def default_partitions() -> list[dict]:
    from pwa_pipeline.pipeline.partitions import default_keys

    keys = default_keys()
    with tempfile.TemporaryDirectory() as tmp:
        # create the MLflow store first: its one-off migration is not the pipeline's cost
        from mlflow.tracking import MlflowClient
        MlflowClient(tracking_uri=f"sqlite:///{Path(tmp) / 'mlflow.db'}").search_experiments()
        return _materialise(keys, Path(tmp), cache=True)


def sweep_child(cache: bool) -> None:
    """Run in a subprocess with PWA_HPARAMS set: materialise the 12 sweep sets."""
    from pwa_pipeline.pipeline.partitions import all_keys

    keys = [k for k in all_keys() if k.startswith("hure_vasak|")]
    with tempfile.TemporaryDirectory() as tmp:
        from mlflow.tracking import MlflowClient
        MlflowClient(tracking_uri=f"sqlite:///{Path(tmp) / 'mlflow.db'}").search_experiments()
        print(json.dumps(_materialise(keys, Path(tmp), cache)))


def sweep() -> dict:
    lines = []
    for i, eps in enumerate(EPS):
        for j, mp in enumerate(MIN_PTS):
            for ds, extra in (("hure_vasak", "na = 1\nnb = 1\nn_rho = 18"),
                              ("kuka_robot", "na = 2\nnb = 2\nn_rho = 61")):
                lines.append(f"[sweep_{i}{j}.{ds}]\nsettings = \"paper\"\n{extra}\n"
                             f"eps = {eps}\nmin_pts = {mp}\n")
    lines.append("[baselines.hure_vasak]\nsubspace_order = 2\nwarmup = 10\n"
                 "[baselines.kuka_robot]\nsubspace_order = 12\nwarmup = 10\n")
    out = {}
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as fh:
        fh.write("\n".join(lines))
    env = {**os.environ, "PWA_HPARAMS": fh.name}
    for cache in (True, False):
        proc = subprocess.run([sys.executable, __file__, "--sweep-child", str(int(cache))],
                              env=env, capture_output=True, text=True, cwd=ROOT)
        if proc.returncode:
            raise RuntimeError(f"sweep subprocess failed:\n{proc.stderr[-3000:]}")
        rows = json.loads(proc.stdout.strip().splitlines()[-1])
        out["with_cache" if cache else "without_cache"] = rows
    os.unlink(fh.name)
    return out


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--sweep-child":
        sweep_child(bool(int(sys.argv[2])))
        return
    defaults = default_partitions()
    for r in defaults:
        print(f"{r['partition']:22s} {r['seconds']:7.2f} s (local models {r['local_models_seconds']:.2f} s)")
    runs = sweep()
    summary = {}
    for name, rows in runs.items():
        summary[name] = {"total_seconds": sum(r["seconds"] for r in rows),
                         "median_run_seconds": statistics.median(r["seconds"] for r in rows),
                         "local_models_seconds": sum(r["local_models_seconds"] for r in rows),
                         "runs_from_cache": sum(r["from_cache"] for r in rows)}
    saved = summary["without_cache"]["total_seconds"] - summary["with_cache"]["total_seconds"]
    summary["saved_seconds"] = saved
    summary["saved_share"] = saved / summary["without_cache"]["total_seconds"]
    print(json.dumps(summary, indent=2))
    write_json({"default_partitions": defaults, "sweep": runs, "sweep_summary": summary},
               "pipeline")
    md = ["## Materialising the default partitions\n",
          pd.DataFrame(defaults).to_markdown(index=False, floatfmt=".3g"), "",
          "## Sweep of 12 ε/MinPts sets on hure_vasak (paper setting, n_rho = 18)\n",
          pd.DataFrame(summary).drop(columns=["saved_seconds", "saved_share"])
          .T.to_markdown(floatfmt=".3g"), "",
          f"Saved by the local-model cache: {saved:.2f} s "
          f"({summary['saved_share']:.1%} of the sweep without it)."]
    (RESULTS / "pipeline.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
