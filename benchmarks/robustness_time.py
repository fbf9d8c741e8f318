"""Fit time of the default (issue 10's target: at most 2× the fit time before issue 10), this
code against earlier commits, in one run.

Fits: the section 5 system at 20 dB and 30 dB (records of ``benchmarks.robustness``,
evaluation seeds 5000…; or other ``--cases``, ``--set tune``) and the robot's training
record (``PWARX.default`` of the ``default`` set, as ``benchmarks.speed`` times it). Each fit
runs in a fresh subprocess, once with this checkout's package and once with each
``--against`` commit's (unpacked with ``git archive``), ``--repeats`` times, the versions
interleaved so that they share the machine's load; the 1-minute load average is recorded
at the start and the end. Reported per fit and version: median wall and CPU seconds (CPU:
the process's, BLAS threads included), the sub-model step's median wall seconds, the number
of sub-models, and the wall and CPU ratios to the first ``--against`` commit; and the wall
seconds of the same fit again in the same process and their ratio (without what a process
pays once, such as numba's start, about 0.5 s, where the version uses it). Then the median
ratio and the number of fits above 2×, for the first and the second fit.

``--parts`` (the checkout only): in the same process, after those two fits, the fit with
step 6 as the plain region SVM (``regions=SVMRegions()``: no residual gate, issue 10's region
estimation left out) and the fit without step 5's split search
(``submodels=RefinedSubModels(split_tol=None)``: what finds modes that moderate noise
merged), their seconds and sub-model counts, and the second fit's ratio to the first: what
the region estimation costs, and what the split search does; in the summary, the median of
each ratio and the fit without the split search against the reference's second fit.

Writes results/robustness_time{suffix}.json and .md. Usage::

    python -m benchmarks.robustness_time [--against bc9084d,15191f1] [--repeats 3]
        [--seeds 2] [--set eval|tune] [--cases paper-20dB] [--no-robot] [--parts]
        [--suffix _tune]
"""

import argparse
import json
import os
import statistics
import tempfile
from pathlib import Path

import pandas as pd

from benchmarks._common import RESULTS, in_fresh_process, previous_tree, write_json
from benchmarks._fits import default_fit
from benchmarks.robustness import FIRST_SEED

ROOT = Path(__file__).resolve().parents[1]


def worker(fit: str, *rest: str) -> None:
    """One fit (``case:seed`` or ``robot``) in this process, then the same fit again, and with
    ``parts`` before the output path the two variants of ``--parts``; their seconds to the
    output path (the last argument)."""
    import time

    from sklearn.base import clone

    est, u, y = default_fit(fit)
    t0, cpu0 = time.perf_counter(), time.process_time()
    model = est.fit(u, y)
    result = {"seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - cpu0,
              "n_submodels": int(model.n_submodels_),
              "submodels_seconds": model.timings_["submodels"]}
    t0 = time.perf_counter()
    est.fit(u, y)
    result["second_seconds"] = time.perf_counter() - t0
    if rest[:-1] == ("parts",):
        from pwa_pipeline.pwa import SVMRegions
        from pwa_pipeline.pwa.steps.submodels import RefinedSubModels

        for name, variant in (("svm_regions", {"regions": SVMRegions()}),
                              ("no_split", {"submodels": RefinedSubModels(split_tol=None)})):
            t0 = time.perf_counter()
            part = clone(est).set_params(**variant).fit(u, y)
            result.update({f"{name}_seconds": time.perf_counter() - t0,
                           f"{name}_submodels": int(part.n_submodels_)})
    Path(rest[-1]).write_text(json.dumps(result))


def _spread(ratios: pd.Series) -> dict:
    """Median of the fits' ratios, how many exceed 2, and how many fits there are."""
    return {"median": float(ratios.median()), "above 2": int((ratios > 2).sum()),
            "fits": len(ratios)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default="bc9084d,15191f1",
                        help="comma-separated commits; the first is the ratios' reference")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seeds", type=int, default=2, help="seeds per case")
    parser.add_argument("--set", choices=list(FIRST_SEED), default="eval",
                        help="seed set of benchmarks.robustness (tune: for tuning)")
    parser.add_argument("--cases", default="paper-20dB,paper-30dB",
                        help="comma-separated cases of benchmarks.robustness")
    parser.add_argument("--no-robot", action="store_true", help="leave the robot's fit out")
    parser.add_argument("--parts", action="store_true",
                        help="also time the checkout without the residual gate and without "
                             "the split search")
    parser.add_argument("--suffix", default="", help="appended to the result file names")
    parser.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(*args.worker)
        return
    first = FIRST_SEED[args.set]
    fits = [f"{case}:{seed}" for case in args.cases.split(",")
            for seed in range(first, first + args.seeds)] + ([] if args.no_robot else ["robot"])
    load_start = os.getloadavg()[0]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trees = {"this": ROOT}
        for commit in args.against.split(","):
            tree = previous_tree(commit, tmp / commit)
            if tree is not None:
                trees[commit] = tree
        for repeat in range(args.repeats):
            for fit in fits:
                for version, tree in trees.items():
                    parts = ["parts"] if args.parts and version == "this" else []
                    rows.append({"fit": fit, "version": version, "repeat": repeat,
                                 **in_fresh_process("benchmarks.robustness_time",
                                                    [fit, *parts], tmp, tree)})
    load_end = os.getloadavg()[0]
    df = pd.DataFrame(rows)
    table = (df.groupby(["fit", "version"], sort=False)
             .agg(median_seconds=("seconds", "median"),
                  cpu_seconds=("cpu_seconds", "median"),
                  second_fit_seconds=("second_seconds", "median"),
                  submodels_seconds=("submodels_seconds", "median"),
                  n_submodels=("n_submodels", statistics.mode)).reset_index())
    if args.parts:
        parts = (df[df["version"] == "this"].groupby("fit", sort=False)
                 .agg(svm_regions_seconds=("svm_regions_seconds", "median"),
                      svm_regions_submodels=("svm_regions_submodels", statistics.mode),
                      no_split_seconds=("no_split_seconds", "median"),
                      no_split_submodels=("no_split_submodels", statistics.mode)))
        table = table.join(parts, on="fit")
        table.loc[table["version"] != "this", list(parts.columns)] = float("nan")
        table["second fit / SVM regions"] = (table["second_fit_seconds"]
                                             / table["svm_regions_seconds"])
    reference = args.against.split(",")[0]
    ref = table[table["version"] == reference].set_index("fit")["median_seconds"]
    table["ratio_to_" + reference] = table["median_seconds"] / table["fit"].map(ref)
    cpu = table[table["version"] == reference].set_index("fit")["cpu_seconds"]
    table["CPU ratio"] = table["cpu_seconds"] / table["fit"].map(cpu)
    second = table[table["version"] == reference].set_index("fit")["second_fit_seconds"]
    table["second fit ratio"] = table["second_fit_seconds"] / table["fit"].map(second)
    ours = table[table["version"] == "this"]
    summary = {name: _spread(ours[col])
               for name, col in (("first fit", "ratio_to_" + reference),
                                 ("second fit", "second fit ratio"))}
    if args.parts:
        summary["second fit / SVM regions"] = _spread(ours["second fit / SVM regions"])
        summary["without the split search, to the reference's second fit"] = _spread(
            ours.set_index("fit")["no_split_seconds"] / second)
    meta = {"repeats": args.repeats, "seed set": args.set, "load average at start": load_start,
            "load average at end": load_end, "versions": list(trees)}
    write_json({"meta": meta, "runs": rows, "table": table.to_dict("records"),
                "ratios of this checkout": summary},
               "robustness_time" + args.suffix)
    text = (f"Fit time, each fit in a fresh process, {args.repeats} repeats interleaved, "
            f"seed set `{args.set}`; "
            f"1-minute load {load_start:.2f} at the start, {load_end:.2f} at the end "
            f"(2 CPUs, shared machine). Versions: `this` (the checkout), "
            f"{', '.join(f'`{v}`' for v in trees if v != 'this')}.\n\n"
            + table.to_markdown(index=False, floatfmt=".3g") + "\n\nRatios of `this` to "
            f"`{reference}`: "
            + "; ".join(f"{name}: median {v['median']:.2f}, above 2 on {v['above 2']} of "
                        f"{v['fits']} fits" for name, v in summary.items()) + "\n")
    (RESULTS / f"robustness_time{args.suffix}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
