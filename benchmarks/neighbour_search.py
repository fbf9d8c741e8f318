"""The exact neighbour search of step 2 on the robot, this checkout against an earlier commit.

On the KUKA training record's regressors (na = nb = 2, 39,856 rows, z-scored as the default's
``local_sets`` searches them, 24 columns), ``nearest_neighbours`` at k = 72 (the default's
n_ρ = 3d) runs in a fresh process per version, twice in each (the second search is timed
apart from thread pools and memory first touched), ``--repeats`` times, the versions
alternated so that they share the machine's load. Reported: median seconds of the first and
second search per version, their ratio, the second search's CPU seconds (all threads; less
sensitive than wall time to a shared machine's load) and their ratio, and whether both
versions return the same neighbours (a hash of the index array). The 1-minute load average
is recorded at the start and the end.

Writes results/neighbour_search.json and .md (``--cold-cache``: neighbour_search_cold.*, this
checkout's numba kernels compiled in every process, as in a fresh clone). Usage::

    python -m benchmarks.neighbour_search [--against bf2d52f] [--repeats 5] [--cold-cache]
"""

import argparse
import hashlib
import json
import os
import statistics
import time
from pathlib import Path

import pandas as pd

from benchmarks._common import RESULTS, against_commit, write_json


def worker(k: str, out: str) -> None:
    """Two searches of the robot's z-scored regressors in this process; seconds and a hash
    of the neighbours to ``out``."""
    from pwa_pipeline import load_kuka
    from pwa_pipeline._validation import as_experiments
    from pwa_pipeline.pwa.steps.neighbours import nearest_neighbours
    from pwa_pipeline.regressors import build_regressors

    robot = load_kuka()
    phi = build_regressors(as_experiments(robot.u_train, robot.y_train), 2, 2, True).phi
    std = phi.std(axis=0)
    x = (phi[:, std > 0] - phi[:, std > 0].mean(axis=0)) / std[std > 0]
    seconds, cpu = [], []
    for _ in range(2):
        t0, c0 = time.perf_counter(), time.process_time()
        idx = nearest_neighbours(x, int(k))
        seconds.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    Path(out).write_text(json.dumps({"first": seconds[0], "second": seconds[1],
                                     "first_cpu": cpu[0], "second_cpu": cpu[1],
                                     "hash": hashlib.blake2b(idx.tobytes()).hexdigest()}))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default="bf2d52f", help="the reference commit")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--k", type=int, default=72)
    parser.add_argument("--cold-cache", action="store_true",
                        help="compile this checkout's numba kernels anew in each process (an "
                             "empty NUMBA_CACHE_DIR, as a fresh clone); writes "
                             "neighbour_search_cold.*")
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(*args.worker)
        return
    load_start = os.getloadavg()[0]
    cold = (lambda r, tmp: {"NUMBA_CACHE_DIR": str(tmp / f"numba-cache-{r}")}) \
        if args.cold_cache else None
    runs = against_commit("benchmarks.neighbour_search", [str(args.k)], args.against,
                          args.repeats, this_env=cold)
    load_end = os.getloadavg()[0]
    rows = [{"version": v, "median first search s": statistics.median(r["first"] for r in rs),
             "median second search s": statistics.median(r["second"] for r in rs),
             "median second search CPU s": statistics.median(r["second_cpu"] for r in rs)}
            for v, rs in runs.items()]
    table = pd.DataFrame(rows)
    ref = table.iloc[1]
    table["second over reference"] = table["median second search s"] / ref[
        "median second search s"]
    table["CPU over reference"] = table["median second search CPU s"] / ref[
        "median second search CPU s"]
    same = {r["hash"] for rs in runs.values() for r in rs}
    head = (f"`nearest_neighbours` at k = {args.k} on the robot's z-scored regressors "
            f"(39,856 × 24), {args.repeats} fresh processes per version alternated, two "
            f"searches each; 1-minute load {load_start:.2f} at the start, {load_end:.2f} at "
            f"the end, {os.cpu_count()} CPUs. Same neighbours in every run: {len(same) == 1}."
            + (" This checkout's kernels compiled anew in each of its processes (empty numba "
               "cache): its first search includes their compilation." if args.cold_cache
               else ""))
    name = "neighbour_search_cold" if args.cold_cache else "neighbour_search"
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{name}.md").write_text(
        head + "\n\n" + table.to_markdown(index=False, floatfmt=".3g") + "\n")
    write_json({"against": args.against, "k": args.k, "load": [load_start, load_end],
                "cold_cache": args.cold_cache, "same_neighbours": len(same) == 1,
                "runs": runs}, name)
    print(head)
    print(table.to_markdown(index=False, floatfmt=".3g"))


if __name__ == "__main__":
    main()
