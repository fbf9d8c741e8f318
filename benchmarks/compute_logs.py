"""What capturing a run's compute logs costs, with Dagster's manager and with the thread-mirrored
one the command line's ``dagster.yaml`` configures.

Two Dagster homes differ only in their ``compute_logs`` entry: Dagster's
``LocalComputeLogManager`` (a ``tail -F`` and a watcher process per stream, four per run)
and :class:`~pwa_pipeline.orchestration.compute_logs.ThreadMirroredComputeLogManager`; both
otherwise :func:`~pwa_pipeline.orchestration.instance.dagster_yaml`'s. On each, the robot
sweep's graph with every asset a no-op (``benchmarks.event_log``'s floor: 15 assets, 47
inputs) is materialised for the 12 sets, ``--rounds`` times, the two homes alternating run by
run so that they share the machine's load. Reported: the median seconds of a run with each,
their difference and ratio, and how busy the machine was (``MachineLoad``).

Writes results/compute_logs.json and results/compute_logs.md.
Usage: python -m benchmarks.compute_logs [--rounds 3]
"""

import argparse
import statistics
import tempfile
from pathlib import Path

import dagster as dg
import pandas as pd

from benchmarks._common import RESULTS, MachineLoad, describe_load, write_json
from benchmarks.event_log import _floor_run, home_instance, noop_assets
from benchmarks.pipeline import sweep_definitions
from pwa_pipeline.orchestration.instance import dagster_yaml

MANAGERS = {
    "dagster": "module: dagster._core.storage.local_compute_log_manager\n"
               "  class: LocalComputeLogManager",
    "thread": "module: pwa_pipeline.orchestration.compute_logs\n"
              "  class: ThreadMirroredComputeLogManager",
}
"""Each arm's compute log manager: its module and class lines in ``dagster.yaml``."""


def _instance(home: Path, manager: str) -> dg.DagsterInstance:
    """A home of ``dagster_yaml`` with the compute logs of ``manager``."""
    text = dagster_yaml(home)
    assert MANAGERS["thread"] in text
    instance = home_instance(home, text.replace(MANAGERS["thread"], MANAGERS[manager]))
    assert type(instance.compute_log_manager).__name__ == MANAGERS[manager].split()[-1]
    return instance


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    load = MachineLoad()
    seconds: dict[str, list[float]] = {name: [] for name in MANAGERS}
    with tempfile.TemporaryDirectory() as tmp:
        defs, keys = sweep_definitions("kuka_robot", Path(tmp))
        assets = noop_assets(defs)
        instances = {name: _instance(Path(tmp) / name / "home", name) for name in MANAGERS}
        for _ in range(args.rounds):
            for key in keys:
                for name, instance in instances.items():
                    run = _floor_run(assets, key, Path(tmp) / name, instance)
                    assert run["success"]
                    seconds[name].append(run["seconds"])
        for instance in instances.values():
            instance.dispose()
    machine = load.summary()
    median = {name: statistics.median(values[1:]) for name, values in seconds.items()}
    summary = {"runs_each": len(seconds["thread"]), "median_seconds": median,
               "saved_seconds": median["dagster"] - median["thread"],
               "dagster_over_thread": median["dagster"] / median["thread"]}
    write_json({"seconds": seconds, "summary": summary, "machine_load": machine},
               "compute_logs")
    table = pd.DataFrame({"median seconds a run": median}).rename_axis("compute logs")
    text = (f"The robot sweep's graph, every asset a no-op, {summary['runs_each']} runs on each "
            f"home (their first left out of the median), alternated; {describe_load(machine)}."
            f"\n\n{table.to_markdown(floatfmt='.3f')}\n\n"
            f"Dagster's manager costs {summary['saved_seconds']:.3f} s more a run "
            f"({summary['dagster_over_thread']:.2f}x the thread-mirrored one's).\n")
    (RESULTS / "compute_logs.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
