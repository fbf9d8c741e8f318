"""The default fit on the robot step by step, this checkout against an earlier commit.

``PWARX.default`` on the KUKA training record (the ``default`` variant of
``benchmarks.speed``, whose worker runs each fit) in a fresh process per version,
``--repeats`` times, the versions alternated so that they share the machine's load. Reported
per version: the median wall and CPU seconds (process time of all threads) of the fit and of
each step, the ratio of the earlier commit's medians to this checkout's, and whether both
give the same clustering labels and sub-models (largest |Δθ| of the first runs). The 1-minute
load average is recorded at the start and the end.

Writes results/default_steps.json and .md. Usage::

    python -m benchmarks.default_steps [--against ba13a41] [--repeats 5]
"""

import argparse
import os
import statistics

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, against_commit, write_json

STEPS = ("local_models", "clustering", "submodels", "regions")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default="ba13a41")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    load_start = os.getloadavg()[0]
    runs = against_commit("benchmarks.speed", ["default"], args.against, args.repeats,
                          report=lambda i, name, res: print(
                              f"run {i + 1}, {name}: {res['seconds']:.2f} s wall, "
                              f"{res['cpu_seconds']:.2f} s CPU", flush=True))
    load_end = os.getloadavg()[0]
    rows = []
    for what, wall, cpu in [("fit", "seconds", "cpu_seconds")] + [
            (s, ("steps", s), ("cpu_steps", s)) for s in STEPS]:
        row = {"step": what}
        for name, res in runs.items():
            for clock, key in (("wall", wall), ("CPU", cpu)):
                get = (lambda r, k=key: r[k]) if isinstance(key, str) else (
                    lambda r, k=key: r[k[0]][k[1]])
                row[f"{name} {clock}"] = statistics.median(get(r) for r in res)
        for clock in ("wall", "CPU"):
            row[f"{args.against} / this, {clock}"] = (
                row[f"{args.against} {clock}"] / row[f"this {clock}"])
        rows.append(row)
    table = pd.DataFrame(rows)
    a, b = runs["this"][0], runs[args.against][0]
    checks = {"same clustering labels": a["labels"] == b["labels"],
              "largest sub-model difference": float(
                  np.abs(np.array(a["thetas"]) - np.array(b["thetas"])).max())
              if np.shape(a["thetas"]) == np.shape(b["thetas"]) else "different shapes"}
    write_json({"against": args.against, "repeats": args.repeats,
                "load_average_1min": {"start": load_start, "end": load_end},
                "cpus": len(os.sched_getaffinity(0)), "steps": rows, "checks": checks,
                "runs": {k: [{"seconds": r["seconds"], "cpu_seconds": r["cpu_seconds"],
                              "steps": r["steps"], "cpu_steps": r["cpu_steps"]} for r in v]
                         for k, v in runs.items()}}, "default_steps")
    md = [f"The default fit on the robot, this checkout against `{args.against}`: "
          f"{args.repeats} fresh processes per version, alternated; medians, seconds. "
          f"1-minute load average {load_start:.2f} at the start, {load_end:.2f} at the end, "
          f"{len(os.sched_getaffinity(0))} CPUs.\n",
          table.to_markdown(index=False, floatfmt=".3g"), "",
          "Checks (first runs): " + "; ".join(f"{k}: {v}" for k, v in checks.items())]
    (RESULTS / "default_steps.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
