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

Before the sweeps, one set is materialised untimed (:func:`warm_up`), so that what the
process pays once falls on no arm. The whole sweep is then run ``--sweeps`` times, one
after the other: the first set of a sweep
(which computes everything) is one sample, which moved the speed-up by 0.27 between two
runs of the same code. Reported per sweep and arm: the total seconds, the first set, the
median of the later sets; per sweep: the speed-up of the caches with each event log
(:func:`summarise`), the best speed-up the floor leaves the pooled arm, were everything but
Dagster's work free in the later sets (the sweep without the caches over its first set with
them + 11 floor sets), and what a set would have to save for the pooled arm to reach issue
12's 3x (:func:`seconds_to_target`); the median speed-up over the sweeps; each step's median
over the later sets of every sweep. How busy the machine was (``MachineLoad``) is recorded
over the whole run.
Writes results/event_log.json and results/event_log.md.
Usage: python -m benchmarks.event_log [--sweeps 3] [--logs dagster pooled]
"""

import argparse
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


def sweep(logs: tuple[str, ...]) -> dict[str, list[dict]]:
    """One robot sweep in each arm (event logs ``logs``, the caches on and off) and the floor,
    each on a new home with new stores, the arms alternating set by set so that they share
    the machine's load; a row per set and arm."""
    runs: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        defs, keys = sweep_definitions("kuka_robot", Path(tmp))
        arms = {f"{log}|{'with' if cache else 'without'}_cache": (log, cache)
                for log in logs for cache in (True, False)}
        folders, instances = {}, {}
        for name, (log, _) in [*arms.items(), ("floor", ("pooled", None))]:
            folders[name] = Path(tmp) / name.replace("|", "_")
            folders[name].mkdir()
            instances[name] = _instance(folders[name] / "dagster_home", log)
            runs[name] = []
        floor = noop_assets(defs)
        for key in keys:
            for name, (log, cache) in arms.items():
                runs[name] += _materialise(defs, [key], folders[name], cache, instances[name])
            runs["floor"].append(_floor_run(floor, key, folders["floor"], instances["floor"]))
        for instance in instances.values():
            instance.dispose()
    return runs


def warm_up() -> None:
    """The sweep's first set materialised once, untimed, on a scratch home with the caches
    on: what a process pays once (imports, numba's start, MLflow's first store) would
    otherwise fall on the first arm of the first sweep's first set alone (5.7 s with the
    caches against 4.0 s without in the run at ``0e33a5d``, whose later sweeps' first sets
    took 3.2–4.5 s in either arm)."""
    with tempfile.TemporaryDirectory() as tmp:
        defs, keys = sweep_definitions("kuka_robot", Path(tmp))
        instance = _instance(Path(tmp) / "dagster_home", "pooled")
        _materialise(defs, keys[:1], Path(tmp), True, instance)
        instance.dispose()


def summarise(runs: dict[str, list[dict]], logs: tuple[str, ...]) -> dict:
    """One sweep's totals per arm, the caches' speed-up with each event log, the best the
    floor leaves the pooled arm, and what 3x needs (:func:`seconds_to_target`)."""
    arms = {name: {"total_seconds": sum(r["seconds"] for r in rows),
                   "first_set_seconds": rows[0]["seconds"],
                   "later_sets_median_seconds": statistics.median(r["seconds"]
                                                                  for r in rows[1:]),
                   "succeeded": sum(r["success"] for r in rows)}
            for name, rows in runs.items()}
    n = len(runs["floor"])
    total = {name: arm["total_seconds"] for name, arm in arms.items()}
    return {"arms": arms,
            "speed_up": {log: total[f"{log}|without_cache"] / total[f"{log}|with_cache"]
                         for log in logs},
            "best_speed_up_over_floor": total["pooled|without_cache"] / (
                arms["pooled|with_cache"]["first_set_seconds"]
                + (n - 1) * arms["floor"]["later_sets_median_seconds"]),
            "seconds_to_3x": seconds_to_target(total["pooled|without_cache"],
                                               total["pooled|with_cache"], n)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweeps", type=int, default=3,
                        help="whole sweeps, one after the other (default 3)")
    parser.add_argument("--logs", nargs="+", choices=list(EVENT_LOGS), default=list(EVENT_LOGS),
                        help="the event logs' arms (default both; the floor is always run)")
    args = parser.parse_args(argv)
    logs = tuple(args.logs)
    if "pooled" not in logs:
        parser.error("--logs must include pooled (the floor and the 3x arithmetic are its)")
    load = MachineLoad()
    warm_up()
    sweeps = [sweep(logs) for _ in range(args.sweeps)]
    machine = load.summary()
    summaries = [summarise(runs, logs) for runs in sweeps]
    median_speed_up = {log: statistics.median(s["speed_up"][log] for s in summaries)
                       for log in logs}
    write_json({"sweeps": sweeps, "summaries": summaries, "median_speed_up": median_speed_up,
                "machine_load": machine}, "event_log")
    totals = pd.DataFrame([{"sweep": i + 1, "arm": name, **arm}
                           for i, s in enumerate(summaries) for name, arm in s["arms"].items()])
    per_sweep = pd.DataFrame([{
        "sweep": i + 1, **{f"speed-up, {log}": s["speed_up"][log] for log in logs},
        "best over the floor": s["best_speed_up_over_floor"],
        "3x: later sets less, caches only (s)": s["seconds_to_3x"]["with_cache_only"],
        "3x: every set less, both arms (s)": s["seconds_to_3x"]["every_set"]}
        for i, s in enumerate(summaries)])
    steps = asset_medians({name: [row for runs in sweeps for row in runs[name][1:]]
                           for name in sweeps[0]})
    text = "\n".join([
        f"The robot's 12-set sweep (benchmarks.pipeline's) on a Dagster home of sqlite files, "
        f"after one set untimed (the process's warm-up), "
        f"{args.sweeps} sweep(s) one after the other, each with the arms "
        f"({', '.join(logs)} event log, the caches on and off) and the floor alternating set "
        f"by set on new homes and stores; {describe_load(machine)}.\n",
        totals.to_markdown(index=False, floatfmt=".3g"), "",
        "Per sweep: the caches' speed-up over the whole sweep with each event log; the best the "
        "floor (Dagster's work for this graph, every asset a no-op) leaves the pooled arm, were "
        "its later sets to cost no more than the floor; and what the pooled arm's sets would "
        f"have to save for {TARGET:g}x: the later sets with the caches only, or every set in "
        "both arms (work a set does with the caches as without, such as its figures and "
        "MLflow runs).\n",
        per_sweep.to_markdown(index=False, floatfmt=".3g"), "",
        "Median speed-up of the caches over the sweeps: "
        + ", ".join(f"{log} {value:.2f}x" for log, value in median_speed_up.items()) + ".\n",
        "Median seconds of each step over the later sets of every sweep:\n",
        steps.to_markdown(floatfmt=".2f"), ""])
    (RESULTS / "event_log.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
