"""A 12-set sweep over ε and MinPts on the robot: local models reused vs every set recomputed
(issue 12).

The 12 sets are the library default on the KUKA training record (na = nb = 2, n_rho = 72)
with ε × MinPts from EPS × MIN_PTS (ε in the unit-free θ units of the default; the default's
own choice is about 25). ``recompute``: each set is a full ``PWARX.fit``. ``reuse``: the
regressors and the local-model step are fitted once (``PWARX.fit_step``), and each set fits
only its clustering, sub-models and regions on them and joins the steps with
``PWARX.assemble``: what the pipeline's local-model cache does (orchestration/assets.py).
Both give the same sub-models (checked). A set whose ε / MinPts leave DBSCAN without a
cluster fails at the clustering step and is timed all the same. ``--repeats`` alternating
runs of both, medians; the 1-minute load average before and after.

``--every-local-model``: the same with every local model estimated
(``local_models__max_sets=None``, the default before the local-model subset).

Writes results/sweep.json and results/sweep.md (sweep_every.* with --every-local-model).
Usage: python -m benchmarks.sweep [--repeats 3] [--every-local-model]
"""

import argparse
import os
import statistics
import time

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, write_json
from pwa_pipeline import load_kuka
from pwa_pipeline._validation import as_experiments
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.pwa.regressors import build_regressors

EPS = (15.0, 20.0, 25.0, 30.0)
MIN_PTS = (36, 48, 60)


def sets(every: bool = False):
    base = clone(HParamsFile().configuration("default", "kuka_robot").pwa)
    if every:
        base.set_params(local_models__max_sets=None)
    return [clone(base).set_params(clustering__eps=e, clustering__min_pts=m)
            for e in EPS for m in MIN_PTS]


def recompute(u, y, every: bool) -> tuple[float, list]:
    t0 = time.perf_counter()
    out = []
    for est in sets(every):
        try:
            out.append(est.fit(u, y).thetas_)
        except ValueError as exc:
            out.append(str(exc))
    return time.perf_counter() - t0, out


def reuse(u, y, every: bool) -> tuple[float, list]:
    t0 = time.perf_counter()
    models = sets(every)
    reg = build_regressors(as_experiments(u, y), models[0].na, models[0].nb, models[0].affine)
    local = models[0].fit_step("local_models", reg)
    out = []
    for est in models:
        try:
            fitted = {"local_models": local}
            for name in ("clustering", "submodels", "regions"):
                fitted[name] = est.fit_step(name, reg, **fitted)
            out.append(est.assemble(reg, **fitted).thetas_)
        except ValueError as exc:
            out.append(str(exc))
    return time.perf_counter() - t0, out


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
    load_start = os.getloadavg()[0]
    times: dict[str, list[float]] = {"recompute": [], "reuse": []}
    results = {}
    for i in range(args.repeats):
        for name, fn in (("recompute", recompute), ("reuse", reuse)):
            seconds, results[name] = fn(robot.u_train, robot.y_train, every)
            times[name].append(seconds)
            print(f"run {i + 1}, {name}: {seconds:.1f} s", flush=True)
    load_end = os.getloadavg()[0]
    same = all((isinstance(a, str) and a == b) or (not isinstance(a, str) and not isinstance(
        b, str) and np.array_equal(a, b)) for a, b in zip(results["recompute"],
                                                            results["reuse"], strict=True))
    per_set = [{"eps": e, "min_pts": m,
                "n_submodels": r.shape[0] if not isinstance(r, str) else None,
                "error": r if isinstance(r, str) else None}
               for (e, m), r in zip([(e, m) for e in EPS for m in MIN_PTS],
                                    results["reuse"], strict=True)]
    med = {k: statistics.median(v) for k, v in times.items()}
    summary = {"recompute_median_s": med["recompute"], "reuse_median_s": med["reuse"],
               "speed_up": med["recompute"] / med["reuse"], "runs": times,
               "same_sub_models": same,
               "load_average_1min": {"start": load_start, "end": load_end},
               "cpus": len(os.sched_getaffinity(0))}
    print(summary)
    write_json({"summary": summary, "sets": per_set}, stem)
    md = [f"12 sets (ε in {EPS} × MinPts in {MIN_PTS}) of the default"
          f"{' with every local model' if every else ''} on the KUKA training "
          f"record; {args.repeats} alternating runs, medians; 1-minute load average "
          f"{load_start:.2f} at the start, {load_end:.2f} at the end, "
          f"{summary['cpus']} CPUs.\n",
          f"| | seconds (median) | runs |\n|---|---|---|\n"
          f"| every set recomputed | {med['recompute']:.1f} | "
          f"{', '.join(f'{t:.1f}' for t in times['recompute'])} |\n"
          f"| local models reused | {med['reuse']:.1f} | "
          f"{', '.join(f'{t:.1f}' for t in times['reuse'])} |\n",
          f"Speed-up {summary['speed_up']:.2f}x; same sub-models in both: {same}.\n",
          pd.DataFrame(per_set).to_markdown(index=False)]
    (RESULTS / f"{stem}.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
