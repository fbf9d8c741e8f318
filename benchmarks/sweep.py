"""A 12-set sweep over ε and MinPts on the robot: local models and step 5 reused vs every set
recomputed.

The 12 sets are the library default on the KUKA training record (na = nb = 2, n_rho = 72)
with ε × MinPts from EPS × MIN_PTS (ε in the unit-free θ units of the default; the default's
own choice is about 25). ``recompute``: each set is a full ``PWARX.fit``. ``reuse``: each set
is a full ``PWARX.fit`` whose local-model step keeps its result in the pipeline's cache
(``LocalLeastSquares(memory=...)``, a ``SignedMemory`` in a new temporary folder each run),
so the first set estimates the local models and the others read them.
``reuse + step 5``: the same with the pipeline's step-5 cache too (``RefinedSubModels``'s
``memory``): each set whose clustering consolidates to a state an earlier set reached takes
steps 2–4 of step 5 from it. All give the same sub-models (checked). A set whose ε / MinPts leave
DBSCAN without a cluster fails at the clustering step and is timed all the same.
``--repeats`` alternating runs of the three, medians; how busy the machine was
(``MachineLoad``: the load average before and after, the CPU time stolen by the hypervisor).

``--every-local-model``: the same with every local model estimated
(``local_models__max_sets=None``, the default before the local-model subset).

Writes results/sweep.json and results/sweep.md (sweep_every.* with --every-local-model).
Usage: python -m benchmarks.sweep [--repeats 3] [--every-local-model]
"""

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, MachineLoad, describe_load, write_json
from pwa_pipeline import load_kuka
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.orchestration.caches import SignedMemory

EPS = (15.0, 20.0, 25.0, 30.0)
MIN_PTS = (36, 48, 60)


def sets(every: bool = False, **memory):
    """The 12 sets, with ``local_models__memory`` and ``submodels__memory`` when given."""
    base = clone(HParamsFile().configuration("default", "kuka_robot").pwa)
    if every:
        base.set_params(local_models__max_sets=None)
    base.set_params(**memory)
    return [clone(base).set_params(clustering__eps=e, clustering__min_pts=m)
            for e in EPS for m in MIN_PTS]


def fitted(models: list, u, y) -> list:
    """Each set's θ_i, or the error that stopped its fit."""
    out = []
    for est in models:
        try:
            out.append(est.fit(u, y).thetas_)
        except ValueError as exc:
            out.append(str(exc))
    return out


def recompute(u, y, every: bool) -> tuple[float, list]:
    t0 = time.perf_counter()
    out = fitted(sets(every), u, y)
    return time.perf_counter() - t0, out


def reuse(u, y, every: bool, step_5: bool = False) -> tuple[float, list]:
    with tempfile.TemporaryDirectory() as folder:
        memory = {"local_models__memory": SignedMemory(Path(folder), "local_models")}
        if step_5:
            memory["submodels__memory"] = SignedMemory(Path(folder), "sub_models")
        t0 = time.perf_counter()
        out = fitted(sets(every, **memory), u, y)
        seconds = time.perf_counter() - t0
    if step_5:
        HITS.append(memory["submodels__memory"].hits)
    return seconds, out


def reuse_with_step_5(u, y, every: bool) -> tuple[float, list]:
    return reuse(u, y, every, step_5=True)


HITS: list[int] = []
"""Sets of each ``reuse + step 5`` run whose steps 2–4 of step 5 came from the cache."""


ARMS = {"recompute": recompute, "reuse": reuse, "reuse + step 5": reuse_with_step_5}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--every-local-model", action="store_true",
                        help="the default with every local model (local_models__max_sets="
                             "None), written to sweep_every.*")
    args = parser.parse_args(argv)
    every = args.every_local_model
    stem = "sweep_every" if every else "sweep"
    robot = load_kuka()
    load = MachineLoad()
    times: dict[str, list[float]] = {name: [] for name in ARMS}
    results = {}
    for i in range(args.repeats):
        for name, fn in ARMS.items():
            seconds, results[name] = fn(robot.u_train, robot.y_train, every)
            times[name].append(seconds)
            print(f"run {i + 1}, {name}: {seconds:.1f} s", flush=True)
    machine = load.summary()

    def same_as_recompute(name: str) -> bool:
        return all((isinstance(a, str) and a == b) or (
            not isinstance(a, str) and not isinstance(b, str) and np.array_equal(a, b))
            for a, b in zip(results["recompute"], results[name], strict=True))

    same = {name: same_as_recompute(name) for name in ARMS if name != "recompute"}
    per_set = [{"eps": e, "min_pts": m,
                "n_submodels": r.shape[0] if not isinstance(r, str) else None,
                "error": r if isinstance(r, str) else None}
               for (e, m), r in zip([(e, m) for e in EPS for m in MIN_PTS],
                                    results["reuse"], strict=True)]
    med = {k: statistics.median(v) for k, v in times.items()}
    speed_up = {name: med["recompute"] / med[name] for name in ARMS}
    summary = {"median_s": med, "speed_up": speed_up, "runs": times,
               "step_5_cache_hits": HITS, "same_sub_models": same,
               "machine_load": machine,
               "cpus": len(os.sched_getaffinity(0))}
    print(summary)
    write_json({"summary": summary, "sets": per_set}, stem)
    label = {"recompute": "every set recomputed", "reuse": "local models reused",
             "reuse + step 5": "local models and step 5 reused"}
    rows = "".join(f"| {label[name]} | {med[name]:.1f} | "
                   f"{', '.join(f'{t:.1f}' for t in times[name])} | "
                   f"{speed_up[name]:.2f}x |\n" for name in ARMS)
    md = [f"12 sets (ε in {EPS} × MinPts in {MIN_PTS}) of the default"
          f"{' with every local model' if every else ''} on the KUKA training "
          f"record; {args.repeats} alternating runs, medians; {describe_load(machine)}; "
          f"{summary['cpus']} CPUs.\n",
          "| | seconds (median) | runs | speed-up |\n|---|---|---|---|\n" + rows,
          f"Step 5's steps 2–4 came from the cache in {', '.join(map(str, HITS))} of the 12 "
          f"sets (each run); the same sub-models as recomputed: "
          f"{', '.join(f'{label[k]} {v}' for k, v in same.items())}.\n",
          pd.DataFrame(per_set).to_markdown(index=False)]
    (RESULTS / f"{stem}.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
