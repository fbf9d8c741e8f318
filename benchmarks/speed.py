"""Speed and memory on the robot: the default and the paper setting, against the
plain reference and the previous implementation, in one run.

On the full KUKA training record (39,988 samples, na = nb = 2, d = 24, m = 6), each fit in a
fresh subprocess (so that its peak resident memory, VmHWM of /proc/self/status, is its own;
the value just before the fit, with Python, the libraries and the data loaded, is reported
as the baseline), ``--repeats`` times, the runs of every variant interleaved so that they
share the machine's load; each fit's wall seconds and CPU seconds (the process time of all
its threads: the work done, which a loaded machine inflates less than the wall time), and
the wall seconds of a second fit in the same process (without what a process pays once:
numba's start, about 0.3 s, thread pools, memory first touched); steps and memory are the
first fit's, and steps 1–4 are also timed in the second fit. The plain reference is run
twice in its process too, so that its ratio to steps 1–4 is given both ways: first runs
(``plain_over_steps_1_4``) and second runs (``again_plain_over_steps_1_4``):

- ``default``: ``PWARX.default`` (n_rho = 3d = 72, ε from the data, the local models of
  5,000 samples), all steps;
- ``default, every local model``: the same with ``local_models__max_sets=None`` (the local
  model of every sample, as the default before; the plain reference's labels are checked
  against its clustering, and the default's sub-models against its own);
- ``default, n_rho=61``: the same with n_rho = 61 (the setting of benchmarks.identify);
- ``paper``: the paper's setting (n_rho = 61, ε = 8, MinPts = 22, every local model
  clustered, the SVM on every clustered row);
- ``plain steps 1-4``: benchmarks/_plain.py, a plain numpy/scikit-learn version of steps 1–4
  of the default (its labels are checked against the library's clustering);
- ``previous ...``: the default and the paper setting with the code of ``--previous`` (a
  commit before issue 12's changes, unpacked with ``git archive``), if git can provide it.

Before the timed runs, the default and the paper setting are fitted once in each tree,
untimed, so that no timed fit compiles the numba kernels (a tree just unpacked has no numba
cache; its first fit took 7.8 s instead of 1.1 s and peaked 0.13 GB higher).

Then the paper setting's region SVM alone (in this process) at the preset's tolerance 1e-2,
the former 1e-4 and a tight reference (1e-5, ten times the iterations): seconds, whether
the solver converged, the primal objective, and how many regions agree with the
reference's on the training rows and on the held-out test record. How busy the machine
was (``MachineLoad``: the 1-minute load average before and after, the CPU time the
hypervisor stole) is recorded; the last line printed is a summary.

Writes results/speed.json and results/speed.md.
Usage: python -m benchmarks.speed [--repeats 3] [--previous 70cfa4d]
"""

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks._common import (
    RESULTS,
    MachineLoad,
    describe_load,
    in_fresh_process,
    previous_tree,
    write_json,
)

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = ("default", "default, every local model", "default, n_rho=61", "paper",
            "plain steps 1-4")
PREVIOUS = ("default", "paper")


def peak_rss_mb() -> float:
    """High-water mark of this process's resident memory, MB (VmHWM, Linux)."""
    line = next(s for s in Path("/proc/self/status").read_text().splitlines()
                if s.startswith("VmHWM:"))
    return int(line.split()[1]) / 1024


def estimator(variant: str):
    from sklearn.base import clone

    from pwa_pipeline.config import HParamsFile

    hp = HParamsFile()
    if variant.startswith("paper"):
        return clone(hp.configuration("paper", "kuka_robot").pwa)
    est = clone(hp.configuration("default", "kuka_robot").pwa)
    if "every" in variant:
        est.set_params(local_models__max_sets=None)
    return est.set_params(local_models__n_rho=61) if "61" in variant else est


def worker(variant: str, out: str) -> None:
    """One fit in this (fresh) process; seconds, step seconds, memory, results to ``out``."""
    from pwa_pipeline import load_kuka

    robot = load_kuka()
    result: dict = {"variant": variant}
    if variant == "plain steps 1-4":
        from benchmarks._plain import plain_steps_1_to_4

        before = peak_rss_mb()
        t0, c0 = time.perf_counter(), time.process_time()
        labels, eps = plain_steps_1_to_4(robot.u_train, robot.y_train, 2, 2)
        result.update(seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - c0,
                      eps=eps, labels=labels.tolist())
        t0 = time.perf_counter()
        plain_steps_1_to_4(robot.u_train, robot.y_train, 2, 2)  # again, as the fits are
        result.update(second_seconds=time.perf_counter() - t0)
    else:
        est = estimator(variant)
        before = peak_rss_mb()
        t0, c0 = time.perf_counter(), time.process_time()
        model = est.fit(robot.u_train, robot.y_train)
        result.update(seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - c0,
                      peak_mb=peak_rss_mb())
        first = dict(steps=dict(model.timings_))
        t0 = time.perf_counter()
        est.fit(robot.u_train, robot.y_train)  # again, without what a process pays once
        result.update(second_seconds=time.perf_counter() - t0, **first,
                      second_steps=dict(est.timings_),
                      eps=model.steps_["clustering"].eps_, n_submodels=model.n_submodels_,
                      labels=model.steps_["clustering"].labels_.tolist(),
                      thetas=model.thetas_.tolist())
    import pwa_pipeline

    result.setdefault("peak_mb", peak_rss_mb())  # the first fit's (a second one may add)
    result.update(before_mb=before, package=pwa_pipeline.__file__)
    Path(out).write_text(json.dumps(result))


def crammer_singer_objective(svm: "CrammerSinger", z: np.ndarray, labels: np.ndarray) -> float:
    """The primal objective liblinear's Crammer–Singer solver minimises, on the z-scored rows
    ``z``: ½ Σ_i (‖w_i‖² + b_i²) + C Σ_k max(0, max_{i≠y_k} 1 + s_i(k) − s_{y_k}(k)), with
    s_i = w_i·z + b_i (the intercept is a feature of value 1, so it is regularised too)."""
    w, b = svm.z_coef_, svm.z_intercept_
    score = z @ w.T + b
    own = score[np.arange(len(labels)), labels]
    margin = 1 + score - own[:, None]
    margin[np.arange(len(labels)), labels] = 0
    return float(0.5 * ((w**2).sum() + (b**2).sum())
                 + svm.C * np.maximum(margin.max(axis=1), 0).sum())


class CrammerSinger:
    """LinearSVC as :class:`pwa_pipeline.pwa.steps.regions.SVMRegions` calls it (z-scored rows),
    keeping the z-scored hyperplanes and whether the solver converged."""

    def __init__(self, C: float, tol: float, max_iter: int):
        self.C, self.tol, self.max_iter = C, tol, max_iter

    def fit(self, z: np.ndarray, labels: np.ndarray) -> "CrammerSinger":
        import warnings

        from sklearn.exceptions import ConvergenceWarning
        from sklearn.svm import LinearSVC

        svm = LinearSVC(C=self.C, multi_class="crammer_singer", max_iter=self.max_iter,
                        random_state=0, tol=self.tol)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            svm.fit(z, labels)
        self.converged_ = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
        self.z_coef_, self.z_intercept_ = svm.coef_, svm.intercept_
        return self

    def predict(self, z: np.ndarray) -> np.ndarray:
        return np.argmax(z @ self.z_coef_.T + self.z_intercept_, axis=1)


def svm_tolerance() -> list[dict]:
    """The paper setting's region SVM on its own clustering at the preset's tolerance 1e-2,
    the former 1e-4 (both with the library's max_iter 50,000) and a reference 1e-5 with
    max_iter 500,000: seconds, convergence, primal objective, and the share of rows whose
    region is the reference's (training rows, held-out test rows)."""
    from sklearn.base import clone

    from pwa_pipeline import load_kuka
    from pwa_pipeline._validation import as_experiments
    from pwa_pipeline.regressors import build_regressors

    robot = load_kuka()
    est = estimator("paper")
    reg = build_regressors(as_experiments(robot.u_train, robot.y_train), 2, 2, False)
    held = build_regressors(as_experiments(robot.u_test, robot.y_test), 2, 2, False).phi
    steps = est.step_objects()
    local = clone(steps["local_models"]).fit(reg.phi, reg.target)
    labels = clone(steps["clustering"]).fit(local, reg.target).labels_
    keep = labels >= 0
    x, lab = reg.phi[keep], labels[keep]
    mean, std = x.mean(axis=0), x.std(axis=0)
    cols = std > 0
    z, z_held = ((v[:, cols] - mean[cols]) / std[cols] for v in (x, held))
    C = est.regions.C
    rows, fitted = [], {}
    for name, tol, max_iter in (("preset (tol 1e-2)", 1e-2, 50_000),
                                ("former (tol 1e-4)", 1e-4, 50_000),
                                ("reference (tol 1e-5)", 1e-5, 500_000)):
        t0 = time.perf_counter()
        fitted[name] = CrammerSinger(C, tol, max_iter).fit(z, lab)
        rows.append({"solve": name, "seconds": time.perf_counter() - t0,
                     "converged": fitted[name].converged_,
                     "objective": crammer_singer_objective(fitted[name], z, lab)})
    ref = fitted["reference (tol 1e-5)"]
    for row in rows:
        svm = fitted[row["solve"]]
        row["objective above reference"] = row["objective"] - rows[-1]["objective"]
        row["same region as reference, training rows"] = float(
            np.mean(svm.predict(z) == ref.predict(z)))
        row["same region as reference, held-out rows"] = float(
            np.mean(svm.predict(z_held) == ref.predict(z_held)))
        row["same region as former, training rows"] = float(
            np.mean(svm.predict(z) == fitted["former (tol 1e-4)"].predict(z)))
    return rows


def _difference(a: list, b: list) -> float | str:
    """Largest absolute difference of two fits' sub-models."""
    if np.shape(a) != np.shape(b):
        return "different shapes"
    return float(np.abs(np.array(a) - np.array(b)).max())


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--previous", default="70cfa4d",
                        help="commit of the implementation before issue 12's changes")
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(*args.worker)
        return
    load = MachineLoad()
    runs: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        old = previous_tree(args.previous, tmp / "previous")
        jobs = [(v, ROOT) for v in VARIANTS]
        if old is not None:
            jobs += [(v, old) for v in PREVIOUS]
        for path in dict.fromkeys(path for _, path in jobs):
            # untimed: the kernels compiled into each tree's numba cache (a tree just
            # unpacked has none, and its first fit would compile them: about 8 s and 0.1 GB)
            for variant in PREVIOUS:
                in_fresh_process("benchmarks.speed", [variant], tmp, path)
        for i in range(args.repeats):
            for variant, path in jobs:
                name = variant if path == ROOT else f"previous {variant}"
                res = in_fresh_process("benchmarks.speed", [variant], tmp, path)
                runs.setdefault(name, []).append(res)
                print(f"run {i + 1}, {name}: {res['seconds']:.2f} s, peak {res['peak_mb']:.0f} MB",
                      flush=True)
    machine = load.summary()
    rows = []
    for name, res in runs.items():
        row = {"variant": name, "median_seconds": statistics.median(r["seconds"] for r in res),
               "median_cpu_seconds": statistics.median(r["cpu_seconds"] for r in res),
               "median_second_fit_seconds": statistics.median(
                   r.get("second_seconds", np.nan) for r in res),
               "runs": [round(r["seconds"], 2) for r in res],
               "peak_mb": max(r["peak_mb"] for r in res),
               "baseline_mb": statistics.median(r["before_mb"] for r in res)}
        if "steps" in res[0]:
            for step in res[0]["steps"]:
                row[f"step_{step}"] = statistics.median(r["steps"][step] for r in res)
            for key, steps in (("steps_1_4", "steps"), ("steps_1_4_again", "second_steps")):
                row[key] = statistics.median(
                    sum(r[steps][s] for s in ("regressors", "local_models", "clustering"))
                    for r in res)
            row["n_submodels"] = res[0]["n_submodels"]
        row["eps"] = res[0]["eps"]
        rows.append(row)
    table = pd.DataFrame(rows).set_index("variant")
    plain = table.loc["plain steps 1-4", "median_seconds"]
    table["plain_over_this_fit"] = plain / table["median_seconds"]
    table["plain_over_steps_1_4"] = plain / table["steps_1_4"]
    table["again_plain_over_steps_1_4"] = (table.loc["plain steps 1-4",
                                                     "median_second_fit_seconds"]
                                           / table["steps_1_4_again"])
    every = runs["default, every local model"][0]
    checks = {
        "plain labels == default (every local model) clustering labels (first run)":
            runs["plain steps 1-4"][0]["labels"] == every["labels"],
        "default: largest sub-model difference from every local model": _difference(
            runs["default"][0]["thetas"], every["thetas"])}
    for name in PREVIOUS:
        if f"previous {name}" in runs:
            a, b = runs[name][0], runs[f"previous {name}"][0]
            checks[f"{name}: same clustering labels as previous"] = a["labels"] == b["labels"]
            checks[f"{name}: largest sub-model difference from previous"] = _difference(
                a["thetas"], b["thetas"])
    svm = svm_tolerance()
    print(table.drop(columns="runs").to_markdown(floatfmt=".3g"))
    print(json.dumps(checks, indent=2))
    print(pd.DataFrame(svm).to_markdown(index=False, floatfmt=".6g"))
    write_json({"machine_load": machine,
                "repeats": args.repeats, "previous_commit": args.previous,
                "fits": table.reset_index().to_dict(orient="records"), "checks": checks,
                "svm_tolerance": svm, "cpus": len(os.sched_getaffinity(0))}, "speed")
    md = [f"Robot training record, {args.repeats} runs of each variant interleaved, each in a "
          f"fresh process; {describe_load(machine)}; {len(os.sched_getaffinity(0))} "
          f"CPUs.\n",
          table.drop(columns="runs").to_markdown(floatfmt=".3g"), "",
          "Checks: " + "; ".join(f"{k}: {v}" for k, v in checks.items()), "",
          "## The paper setting's region SVM (Crammer–Singer, 24,732 rows, 27 classes) by "
          "solver tolerance\n",
          pd.DataFrame(svm).to_markdown(index=False, floatfmt=".6g")]
    summary = (f"summary: default {table.loc['default', 'median_seconds']:.2f} s "
               f"({table.loc['default', 'plain_over_this_fit']:.2f}x the plain steps 1-4; "
               f"its steps 1-4 {table.loc['default', 'plain_over_steps_1_4']:.1f}x, "
               f"{table.loc['default', 'again_plain_over_steps_1_4']:.1f}x run again), "
               f"paper {table.loc['paper', 'median_seconds']:.2f} s with its SVM "
               f"{table.loc['paper', 'step_regions']:.2f} s, peak "
               f"{table.loc['paper', 'peak_mb'] / 1024:.2f} GB; medians of {args.repeats}; "
               f"load {machine['start']:.2f} -> {machine['end']:.2f}, "
               f"{machine['steal_share']:.0%} stolen, on "
               f"{len(os.sched_getaffinity(0))} CPUs")
    md.append("\n" + summary)
    (RESULTS / "speed.md").write_text("\n".join(md) + "\n")
    print(summary)


if __name__ == "__main__":
    main()
