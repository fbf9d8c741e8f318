"""The robot's 12-set sweep on the command line's kind of Dagster home (sqlite files on disk),
with Dagster's own sqlite event log and with the one that keeps its connections open.

``benchmarks.pipeline`` materialises on an ephemeral (in-memory) Dagster instance; the
command line (``python -m pwa_pipeline run``), ``dagster dev`` and the UI's runs store their
events in ``$DAGSTER_HOME``'s sqlite files. Here every set of the robot sweep of
``benchmarks.pipeline`` (default setting, 12 ε/MinPts sets) is materialised in four arms,
each with its own Dagster home and stores, the arms alternating set by set so that they share
the machine's load:

- event log: Dagster's ``SqliteEventLogStorage`` (the ``dagster.yaml`` the command line
  wrote before: Dagster's default storage and compute logs) or
  :class:`~pwa_pipeline.orchestration.event_log.PooledEventLogStorage` (the
  ``dagster.yaml`` of :func:`~pwa_pipeline.orchestration.instance.dagster_yaml`, whose compute
  logs are
  :class:`~pwa_pipeline.orchestration.compute_logs.ThreadMirroredComputeLogManager`'s);
- the caches on or off, as in ``benchmarks.pipeline``;

and a fifth arm, ``floor``: the same graph with every asset a no-op (same keys, partitions
and inputs, each returning 0; without the 4 asset checks) on a home of
:func:`~pwa_pipeline.orchestration.instance.dagster_yaml` and the same asset store: what
Dagster's own work costs a set of this graph, the part of a later set that no cache of ours
can remove.

Reported per arm: the sweep's total seconds, its first set, the median of the later sets,
each step's median; the speed-up of the caches with each event log; and the best speed-up
the floor leaves the pooled arm, were everything but Dagster's work free in the later sets:
the sweep without the caches over (its first set with them + 11 floor sets); and what a set
would have to save for the pooled arm to reach issue 12's 3x (:func:`seconds_to_target`).
How busy the machine was (``MachineLoad``) is recorded over the whole run.
Writes results/event_log.json and results/event_log.md.
Usage: python -m benchmarks.event_log
"""

import statistics
import tempfile
from pathlib import Path

import dagster as dg
import pandas as pd

from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_json
from benchmarks.pipeline import (
    QUIET,
    _materialise,
    asset_medians,
    step_seconds,
    sweep_definitions,
)
from pwa_pipeline.orchestration.instance import _SETTINGS, dagster_yaml
from pwa_pipeline.orchestration.jobs import LEADERBOARD
from pwa_pipeline.orchestration.storage import PartitionedFileIOManager

EVENT_LOGS = {"dagster": lambda home: _SETTINGS, "pooled": dagster_yaml}
"""Each event log arm: the dagster.yaml of its home."""


def home_instance(home: Path, yaml: str) -> dg.DagsterInstance:
    """A Dagster instance on the new home ``home`` whose ``dagster.yaml`` is ``yaml``."""
    home.mkdir(parents=True)
    (home / "dagster.yaml").write_text(yaml)
    return dg.DagsterInstance.from_config(str(home))


def _instance(home: Path, event_log: str) -> dg.DagsterInstance:
    return home_instance(home, EVENT_LOGS[event_log](home))


def noop_assets(defs: dg.Definitions) -> list[dg.AssetsDefinition]:
    """Every partitioned asset of ``defs`` as a no-op: same key, partitions and inputs."""
    graph = defs.resolve_asset_graph()
    assets = []
    for key in graph.toposorted_asset_keys:
        if key.to_user_string() == LEADERBOARD:
            continue
        node = graph.get(key)

        def noop(**_inputs) -> int:
            return 0

        assets.append(dg.asset(name=key.to_user_string(), partitions_def=node.partitions_def,
                               ins={p.to_user_string(): dg.AssetIn(p)
                                    for p in node.parent_keys})(noop))
    return assets


def _floor_run(assets: list, key: str, folder: Path, instance: dg.DagsterInstance) -> dict:
    """One set of the no-op graph, timed as :func:`benchmarks.pipeline._materialise` times
    a set."""
    with Timer() as t:
        result = dg.materialize(
            assets, partition_key=key, instance=instance,
            resources={"io_manager": PartitionedFileIOManager(base_dir=str(folder / "storage"))},
            run_config=QUIET)
    return {"partition": key, "seconds": t.seconds, "success": result.success,
            "assets": step_seconds(result)}


TARGET = 3.0
"""The speed-up of the caches issue 12 asks of this sweep."""


def seconds_to_target(without: float, with_: float, sets: int) -> dict[str, float]:
    """Seconds a set would have to save for the caches' speed-up ``without / with_`` over a
    sweep of ``sets`` to reach :data:`TARGET`: in the later sets with the caches only
    (``with_cache_only``), or in every set of both arms (``every_set``: work done alike with
    and without the caches, ``(without - n s) / (with_ - n s) = TARGET``)."""
    return {"with_cache_only": max(with_ - without / TARGET, 0.0) / (sets - 1),
            "every_set": max(TARGET * with_ - without, 0.0) / ((TARGET - 1) * sets)}


def main() -> None:
    load = MachineLoad()
    runs: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        defs, keys = sweep_definitions("kuka_robot", Path(tmp))
        arms = {f"{log}|{'with' if cache else 'without'}_cache": (log, cache)
                for log in EVENT_LOGS for cache in (True, False)}
        folders = {name: Path(tmp) / name.replace("|", "_") for name in arms}
        instances = {}
        for name, (log, cache) in arms.items():
            folders[name].mkdir()
            instances[name] = _instance(folders[name] / "dagster_home", log)
            runs[name] = []
        floor = noop_assets(defs)
        folders["floor"] = Path(tmp) / "floor"
        folders["floor"].mkdir()
        instances["floor"] = _instance(folders["floor"] / "dagster_home", "pooled")
        runs["floor"] = []
        for key in keys:  # the arms alternate set by set, so that they share the load
            for name, (log, cache) in arms.items():
                runs[name] += _materialise(defs, [key], folders[name], cache, instances[name])
            runs["floor"].append(_floor_run(floor, key, folders["floor"], instances["floor"]))
        for instance in instances.values():
            instance.dispose()
    machine = load.summary()
    summary = {name: {"total_seconds": sum(r["seconds"] for r in rows),
                      "first_set_seconds": rows[0]["seconds"],
                      "later_sets_median_seconds": statistics.median(r["seconds"]
                                                                     for r in rows[1:]),
                      "succeeded": sum(r["success"] for r in rows)}
               for name, rows in runs.items()}
    speed_up = {log: summary[f"{log}|without_cache"]["total_seconds"]
                / summary[f"{log}|with_cache"]["total_seconds"] for log in EVENT_LOGS}
    best = summary["pooled|without_cache"]["total_seconds"] / (
        summary["pooled|with_cache"]["first_set_seconds"]
        + (len(keys) - 1) * summary["floor"]["later_sets_median_seconds"])
    needed = seconds_to_target(summary["pooled|without_cache"]["total_seconds"],
                               summary["pooled|with_cache"]["total_seconds"], len(keys))
    write_json({"runs": runs, "summary": summary, "cache_speed_up": speed_up,
                "best_speed_up_over_floor": best, "seconds_to_3x": needed,
                "machine_load": machine}, "event_log")
    steps = asset_medians({name: rows[1:] for name, rows in runs.items()})
    text = "\n".join([
        f"The robot's 12-set sweep (benchmarks.pipeline's) on a Dagster home of sqlite files, "
        f"four arms and the floor alternating set by set; one run; {describe_load(machine)}.\n",
        pd.DataFrame(summary).T.to_markdown(floatfmt=".3g"), "",
        "Speed-up of the caches over the whole sweep, with each event log: "
        + ", ".join(f"{log} {value:.2f}x" for log, value in speed_up.items()) + ". "
        f"Were the later sets to cost the pooled arm no more than the floor (Dagster's work "
        f"for this graph, every asset a no-op: "
        f"{summary['floor']['later_sets_median_seconds']:.2f} s a set), its speed-up would be "
        f"{best:.2f}x. For {TARGET:g}x, the pooled arm's later sets would have to cost "
        f"{needed['with_cache_only']:.2f} s less each with the caches only, or every set "
        f"{needed['every_set']:.2f} s less in both arms (work that a set does with the caches "
        f"as without, such as its figures and MLflow runs).\n",
        "Median seconds of each step over the later sets:\n",
        steps.to_markdown(floatfmt=".2f"), ""])
    (RESULTS / "event_log.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
