"""Pipeline cost: materialising the default partitions, and what the caches save in sweeps.

1. Time to materialise every asset of each default partition (hure_vasak and kuka_robot with
   the 'paper' and 'default' sets), in-process with dg.materialize, fresh stores.
2. Two sweeps of 12 hyper-parameter sets that differ only in ε and MinPts: the simulated
   system in the paper setting (n_rho = 18), and the robot with the default (the sets of
   benchmarks.sweep). Every asset of every set, once with the caches (local models, step 5,
   the baselines, the scores and figures, ``PipelineSettings.cache_local_models`` /
   ``cache_sub_models`` / ``cache_baselines`` / ``cache_scores``) and once without, the two
   alternating set by set (each in its own stores) so that they share the machine's load;
   the saving is the difference, and each asset's median seconds over the sets are
   reported.
   Each run's row also gives the MB it added to the asset store, MLflow's artifact store
   (the figures, tables and logged models of its three runs) and the caches.
   A set whose ε / MinPts leave DBSCAN without a cluster fails at `clusters` (as it should)
   and is timed all the same. The sweep's sets are a temporary hyper-parameter file, with
   definitions built for it (pwa_pipeline.orchestration.definitions.build_definitions).

How busy the machine was (``MachineLoad``) is recorded over the whole run.
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

from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_json
from benchmarks.sweep import EPS as ROBOT_EPS
from benchmarks.sweep import MIN_PTS as ROBOT_MIN_PTS
from pwa_pipeline.orchestration.definitions import build_definitions, partitions_of
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.jobs import SWEEP_SELECTION
from pwa_pipeline.orchestration.partitions import DEFAULT_SETS, all_keys, runnable_keys
from pwa_pipeline.orchestration.settings import PipelineSettings
from pwa_pipeline.orchestration.tracking import MLflowTracker

EPS = (0.1, 0.15, 0.2, 0.3)
MIN_PTS = (10, 15, 20)


def _megabytes(folder: Path) -> float:
    """What the files below ``folder`` take, in MB."""
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file()) / 1e6


QUIET = {"loggers": {"console": {"config": {"log_level": "ERROR"}}}}
"""Run configuration of a timed run: Dagster's console log at errors only."""


def step_seconds(result: dg.ExecuteInProcessResult) -> dict[str, float]:
    """Each succeeded step's seconds in a run."""
    return {e.step_key: e.event_specific_data.duration_ms / 1000
            for e in result.get_step_success_events()}


def _materialise(defs: dg.Definitions, keys: list[str], tmp: Path, cache: bool,
                 instance: dg.DagsterInstance | None = None) -> list[dict]:
    """Materialise every asset of each partition of ``keys`` with stores under ``tmp`` (the
    caches on or off) on ``instance`` (default: a new ephemeral one); a row per run."""
    # create the MLflow store first: its one-off migration is not the pipeline's cost
    MlflowClient(tracking_uri=f"sqlite:///{tmp / 'mlflow.db'}").search_experiments()
    resources = {
        "io_manager": PartitionedFileIOManager(base_dir=str(tmp / "storage")),
        "settings": PipelineSettings(cache_dir=str(tmp / "cache"), cache_local_models=cache,
                                     cache_sub_models=cache, cache_baselines=cache,
                                     cache_scores=cache,
                                     hparams_path=defs.resources["settings"].hparams_path,
                                     datasets_path=defs.resources["settings"].datasets_path),
        "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{tmp / 'mlflow.db'}"),
    }
    instance = instance or dg.DagsterInstance.ephemeral()
    rows = []
    stores = {"storage": tmp / "storage", "mlflow_artifacts": tmp / "mlartifacts",
              "cache": tmp / "cache"}
    for key in keys:
        before = {name: _megabytes(folder) for name, folder in stores.items()}
        with Timer() as t:
            result = dg.materialize(list(defs.assets), partition_key=key, resources=resources,
                                    selection=SWEEP_SELECTION, instance=instance,
                                    run_config=QUIET, raise_on_error=False)
        done = {e.asset_key.to_user_string(): e.materialization
                for e in result.get_asset_materialization_events()}
        local = done["local_models"].metadata
        subs = [done["sub_models"]] if "sub_models" in done else []
        scored = [done["pwa_scores"]] if "pwa_scores" in done else []
        rows.append({"partition": key, "seconds": t.seconds, "success": result.success,
                     "local_models_seconds": local["seconds"].value,
                     "from_cache": local["from_cache"].value,
                     "step_5_from_cache": bool(subs and subs[0].metadata["from_cache"].value),
                     "pwa_scores_from_cache": bool(
                         scored and scored[0].metadata["scores_from_cache"].value),
                     **{f"{name}_mb_added": _megabytes(folder) - before[name]
                        for name, folder in stores.items()},
                     "assets": step_seconds(result)})
    return rows


def default_partitions() -> list[dict]:
    defs = build_definitions()
    with tempfile.TemporaryDirectory() as tmp:
        keys, _ = runnable_keys(partitions_of(defs), defs.resources["settings"], DEFAULT_SETS)
        return _materialise(defs, keys, Path(tmp), cache=True)


SWEEPS = {
    "hure_vasak": (EPS, MIN_PTS, "preset = \"paper\"\nna = 1\nnb = 1\nlocal_models.n_rho = 18\n",
                   "[baselines.hure_vasak]\nwarmup = 10\nsubspace.order = 2\n"),
    "kuka_robot": (ROBOT_EPS, ROBOT_MIN_PTS, "preset = \"default\"\nna = 2\nnb = 2\n", ""),
}
"""Per data set: its ε and MinPts, the rest of each set, and the baselines' table."""


def sweep_definitions(dataset: str, folder: Path) -> tuple[dg.Definitions, list[str]]:
    """Definitions of the 12-set sweep of ``dataset`` (its hyper-parameter file written to
    ``folder``) and its partition keys."""
    eps_values, min_pts_values, setting, baselines = SWEEPS[dataset]
    lines = [f"[sweep_{i}{j}.{dataset}]\n{setting}clustering.eps = {eps}\n"
             f"clustering.min_pts = {mp}\n"
             for i, eps in enumerate(eps_values) for j, mp in enumerate(min_pts_values)]
    lines.append(baselines)
    path = folder / "sweep.toml"
    path.write_text("\n".join(lines))
    defs = build_definitions(path)
    return defs, [k for k in all_keys(partitions_of(defs)) if k.startswith(f"{dataset}|")]


def sweep(dataset: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        defs, keys = sweep_definitions(dataset, Path(tmp))
        arms = {True: "with_cache", False: "without_cache"}
        out = {name: [] for name in arms.values()}
        for cache in arms:
            (Path(tmp) / f"cache_{cache}").mkdir()
        for key in keys:  # the arms alternate set by set, so that they share the load
            for cache, name in arms.items():
                out[name] += _materialise(defs, [key], Path(tmp) / f"cache_{cache}", cache)
    return out


def summarise(runs: dict) -> dict:
    """Totals of a sweep with and without the caches, and the saving."""
    summary = {}
    for name, rows in runs.items():
        summary[name] = {"total_seconds": sum(r["seconds"] for r in rows),
                         "median_run_seconds": statistics.median(r["seconds"] for r in rows),
                         "local_models_seconds": sum(r["local_models_seconds"] for r in rows),
                         "runs_local_models_from_cache": sum(r["from_cache"] for r in rows),
                         "runs_step_5_from_cache": sum(r["step_5_from_cache"] for r in rows),
                         "runs_pwa_scores_from_cache": sum(r["pwa_scores_from_cache"]
                                                           for r in rows),
                         **{f"{store}_mb": sum(r[f"{store}_mb_added"] for r in rows)
                            for store in ("storage", "mlflow_artifacts", "cache")}}
    saved = summary["without_cache"]["total_seconds"] - summary["with_cache"]["total_seconds"]
    summary["speed_up"] = (summary["without_cache"]["total_seconds"]
                           / summary["with_cache"]["total_seconds"])
    summary["saved_seconds"] = saved
    summary["saved_share"] = saved / summary["without_cache"]["total_seconds"]
    return summary


def asset_medians(runs: dict) -> pd.DataFrame:
    """Each asset's median seconds over the sets, with and without the caches."""
    return pd.DataFrame({name: pd.DataFrame([r["assets"] for r in rows]).median()
                         for name, rows in runs.items()})


def main() -> None:
    load = MachineLoad()
    defaults = default_partitions()
    for r in defaults:
        print(f"{r['partition']:22s} {r['seconds']:7.2f} s (local models {r['local_models_seconds']:.2f} s)")
    sweeps = {dataset: sweep(dataset) for dataset in SWEEPS}
    machine = load.summary()
    summaries = {dataset: summarise(runs) for dataset, runs in sweeps.items()}
    print(json.dumps(summaries, indent=2))
    write_json({"default_partitions": defaults, "sweeps": sweeps, "sweep_summaries": summaries,
                "machine_load": machine}, "pipeline")
    titles = {"hure_vasak": "12 ε/MinPts sets on hure_vasak (paper setting, n_rho = 18)",
              "kuka_robot": "12 ε/MinPts sets on kuka_robot (default; benchmarks.sweep's sets)"}
    md = [f"One run; {describe_load(machine)}.\n", "## Materialising the default partitions\n",
          pd.DataFrame(defaults).drop(columns=["assets"]).to_markdown(index=False,
                                                                      floatfmt=".3g"), ""]
    for dataset, summary in summaries.items():
        md += [f"## Sweep of {titles[dataset]}\n",
               pd.DataFrame({k: v for k, v in summary.items() if isinstance(v, dict)})
               .T.to_markdown(floatfmt=".3g"), "",
               f"Saved by the caches: {summary['saved_seconds']:.2f} s "
               f"({summary['saved_share']:.1%} of the sweep without them; "
               f"{summary['speed_up']:.2f}x).\n", "Median seconds of each asset over the sets:\n",
               asset_medians(sweeps[dataset]).to_markdown(floatfmt=".2f"), ""]
    (RESULTS / "pipeline.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
