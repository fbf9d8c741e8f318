"""Pipeline cost: materialising the default partitions, and what the local-model cache saves.

1. Time to materialise every asset of each default partition (hure_vasak and kuka_robot with
   the 'paper' and 'default' sets), in-process with dg.materialize, fresh stores.
2. A sweep of 12 hyper-parameter sets on the simulated system that differ only in ε and MinPts
   (paper setting, n_rho = 18): every asset of every set, once with the local-model cache and
   once without; the saving is the difference (the local_models step's time reported too).
   A set whose ε / MinPts leave DBSCAN without a cluster fails at `clusters` (as it should)
   and is timed all the same. The sweep's sets are a temporary hyper-parameter file, with
   definitions built for it (pwa_pipeline.orchestration.definitions.build_definitions).

Writes results/pipeline.json and results/pipeline.md.
Usage: python -m benchmarks.pipeline
"""

import json
import statistics
import tempfile
from pathlib import Path

import dagster as dg
import pandas as pd
from mlflow.tracking import MlflowClient

from benchmarks._common import RESULTS, Timer, write_json
from pwa_pipeline.orchestration.definitions import build_definitions, partitions_of
from pwa_pipeline.orchestration.jobs import SWEEP_SELECTION
from pwa_pipeline.orchestration.partitions import DEFAULT_SETS, all_keys, runnable_keys
from pwa_pipeline.orchestration.resources import MLflowTracker, PipelineSettings
from pwa_pipeline.orchestration.storage import PartitionedFileIOManager

EPS = (0.1, 0.15, 0.2, 0.3)
MIN_PTS = (10, 15, 20)


def _materialise(defs: dg.Definitions, keys: list[str], tmp: Path, cache: bool) -> list[dict]:
    # create the MLflow store first: its one-off migration is not the pipeline's cost
    MlflowClient(tracking_uri=f"sqlite:///{tmp / 'mlflow.db'}").search_experiments()
    resources = {
        "io_manager": PartitionedFileIOManager(base_dir=str(tmp / "storage")),
        "settings": PipelineSettings(cache_dir=str(tmp / "cache"), cache_local_models=cache,
                                     hparams_path=defs.resources["settings"].hparams_path,
                                     datasets_path=defs.resources["settings"].datasets_path),
        "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{tmp / 'mlflow.db'}"),
    }
    instance = dg.DagsterInstance.ephemeral()
    quiet = {"loggers": {"console": {"config": {"log_level": "ERROR"}}}}
    rows = []
    for key in keys:
        with Timer() as t:
            result = dg.materialize(list(defs.assets), partition_key=key, resources=resources,
                                    selection=SWEEP_SELECTION, instance=instance,
                                    run_config=quiet, raise_on_error=False)
        local = result.asset_materializations_for_node("local_models")[0].metadata
        rows.append({"partition": key, "seconds": t.seconds, "success": result.success,
                     "local_models_seconds": local["seconds"].value,
                     "from_cache": local["from_cache"].value})
    return rows


def default_partitions() -> list[dict]:
    defs = build_definitions()
    with tempfile.TemporaryDirectory() as tmp:
        keys, _ = runnable_keys(partitions_of(defs), defs.resources["settings"], DEFAULT_SETS)
        return _materialise(defs, keys, Path(tmp), cache=True)


def sweep() -> dict:
    lines = [f"[sweep_{i}{j}.hure_vasak]\npreset = \"paper\"\nna = 1\nnb = 1\n"
             f"local_models.n_rho = 18\nclustering.eps = {eps}\nclustering.min_pts = {mp}\n"
             for i, eps in enumerate(EPS) for j, mp in enumerate(MIN_PTS)]
    lines.append("[baselines.hure_vasak]\nwarmup = 10\nsubspace.order = 2\n")
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sweep.toml"
        path.write_text("\n".join(lines))
        defs = build_definitions(path)
        keys = [k for k in all_keys(partitions_of(defs)) if k.startswith("hure_vasak|")]
        for cache in (True, False):
            run_dir = Path(tmp) / f"cache_{cache}"
            run_dir.mkdir()
            out["with_cache" if cache else "without_cache"] = _materialise(defs, keys, run_dir,
                                                                           cache)
    return out


def main() -> None:
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
