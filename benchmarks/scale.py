"""Scale curve of the default fit: time and peak memory per step against N.

Cases: the simulated system of the paper's section 5 (``make_hure_vasak``, 30 dB, seed 0,
na = nb = 1, d = 4, m = 2) at N = 4,000, 40,000 and 400,000 samples, and the KUKA training
record (39,988 samples in 66 experiments, na = nb = 2, d = 24, m = 6) once and tiled ten
times (its 66 experiments repeated: 399,880 samples whose regressor rows each occur ten
times). Repeated (φ, y) rows count once in steps 2–4
(:class:`~pwa_pipeline.pwa.steps.local_models.LocalLeastSquares`): the tiled record has the
local models and clusters of the record once, and steps 5–6 fit on all 398,560 rows.

Each case runs in a fresh subprocess with the data set's ``default`` hyper-parameter set;
the steps run one after another as ``PWARX.fit`` runs them (:func:`fit_steps`: each step
object fitted on what the steps before it produced), and before each
the process's peak resident memory (VmHWM) is reset (``/proc/self/clear_refs``), so a
step's peak is its own, the data and the previous steps' results included. The memory
guard's estimate (``pwa_pipeline.pwa.memory.fit_memory``, plus the regressors) is reported
beside the measured peak. The exponent b of time ∝ N^b (and of the memory above the
baseline) is fitted on the simulated sizes by least squares on the logarithms.

Writes results/scale.json and results/scale.md.
Usage: python -m benchmarks.scale [--sizes 4000 40000 400000] [--no-robot]
"""

import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, in_fresh_process, write_json

ROOT = Path(__file__).resolve().parents[1]


def rss_mb(field: str = "VmHWM") -> float:
    line = next(s for s in Path("/proc/self/status").read_text().splitlines()
                if s.startswith(field + ":"))
    return int(line.split()[1]) / 1024


def reset_peak() -> bool:
    """Reset VmHWM to the current resident size (Linux ≥ 4.0); False if not possible."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def worker(case: str, size: int, out: str) -> None:
    from sklearn.base import clone

    from pwa_pipeline import load_kuka, make_hure_vasak
    from pwa_pipeline._validation import as_experiments
    from pwa_pipeline.config import HParamsFile
    from pwa_pipeline.pwa.estimator import STEPS
    from pwa_pipeline.pwa.memory import fit_memory
    from pwa_pipeline.regressors import build_regressors

    if case == "simulated":
        data = make_hure_vasak(n_samples=size, snr_db=30.0, seed=0)
        u, y, dataset = data.u_train[0], data.y_train[0], "hure_vasak"
    else:
        robot = load_kuka()
        u, y, dataset = robot.u_train * size, robot.y_train * size, "kuka_robot"
    est = clone(HParamsFile().configuration("default", dataset).pwa)
    baseline = rss_mb("VmRSS")
    t_all = time.perf_counter()
    t0 = time.perf_counter()
    reg = build_regressors(as_experiments(u, y), est.na, est.nb, est.affine)
    rows = [{"step": "regressors", "seconds": time.perf_counter() - t0}]
    n, d = reg.phi.shape
    estimate = fit_memory(n, d, reg.target.shape[1], est.step_objects())
    fitted, error = {}, None
    for name in STEPS:
        resettable = reset_peak()
        t0 = time.perf_counter()
        try:
            fitted[name] = fit_step(est, name, reg, fitted)
        except ValueError as exc:  # e.g. every local set degenerate: timed all the same
            error = f"{name}: {exc}"
        rows.append({"step": name, "seconds": time.perf_counter() - t0,
                     "peak_mb": rss_mb() if resettable else np.nan,
                     "estimate_mb": (estimate[name] + reg.phi.nbytes + reg.target.nbytes)
                     / 2**20 + baseline})
        if error:
            break
    total = time.perf_counter() - t_all
    Path(out).write_text(json.dumps({
        "case": case, "size": size, "rows": n, "d": d, "steps": rows, "seconds": total,
        "baseline_mb": baseline, "peak_mb": max(r.get("peak_mb", 0) for r in rows),
        "n_submodels": None if error else fitted["regions"].n_regions_, "error": error},
        default=float))


def fit_step(est, name: str, reg, fitted: dict):
    """Step ``name`` of ``est`` fitted on the regressors and the steps before it, with the
    arguments ``PWARX.fit`` gives it on the paper's route (the steps' documented ``fit``)."""
    from sklearn.base import clone

    from pwa_pipeline.pwa.steps.submodels import output_lag_columns

    steps = est.step_objects()
    step = clone(steps[name])
    if name == "local_models":
        return step.fit(reg.phi, reg.target)
    if name == "clustering":
        return step.fit(fitted["local_models"], reg.target)
    if name == "submodels":
        return step.fit(reg.phi, reg.target, fitted["local_models"], fitted["clustering"],
                        regions=steps["regions"])
    subs = fitted["submodels"]
    return step.fit(reg.phi, subs.labels_, subs.n_submodels_, sample_weight=subs.weights_,
                    target=reg.target, thetas=subs.thetas_,
                    output_lags=output_lag_columns(reg.n_outputs, est.na, reg.phi.shape[1]),
                    experiment=reg.experiment)


def exponent(sizes, values) -> float:
    """b of values ∝ sizes^b, least squares on the logarithms."""
    return float(np.polyfit(np.log(sizes), np.log(values), 1)[0])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[4000, 40000, 400000])
    parser.add_argument("--no-robot", action="store_true")
    parser.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(args.worker[0], int(args.worker[1]), args.worker[2])
        return
    cases = [("simulated", s) for s in args.sizes]
    if not args.no_robot:
        cases += [("robot", 1), ("robot", 10)]
    load_start = os.getloadavg()[0]
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for case, size in cases:
            try:
                res = in_fresh_process("benchmarks.scale", [case, str(size)], Path(tmp))
            except subprocess.CalledProcessError as exc:
                print(f"{case} {size}: failed ({exc})")
                continue
            res["load_1min"] = os.getloadavg()[0]
            results.append(res)
            print(f"{case} x{size}: {res['rows']} rows, {res['seconds']:.1f} s, peak "
                  f"{res['peak_mb']:.0f} MB, "
                  + ", ".join(f"{r['step']} {r['seconds']:.2f} s" for r in res["steps"]),
                  flush=True)
    load_end = os.getloadavg()[0]
    table, steps = [], []
    for res in results:
        label = (f"simulated, N = {res['size']:,}" if res["case"] == "simulated"
                 else f"robot x{res['size']}")
        table.append({"case": label, "rows": res["rows"], "d": res["d"],
                      "seconds": res["seconds"], "peak_mb": res["peak_mb"],
                      "baseline_mb": res["baseline_mb"], "n_submodels": res["n_submodels"],
                      "load_1min_after": res["load_1min"], "error": res.get("error"),
                      **{f"{r['step']}_s": r["seconds"] for r in res["steps"]}})
        for r in res["steps"]:
            steps.append({"case": label, **r})
    sim = [r for r in results if r["case"] == "simulated"]
    fits = {}
    if len(sim) >= 2:
        n = [r["rows"] for r in sim]
        fits["total seconds"] = exponent(n, [r["seconds"] for r in sim])
        for step in ("local_models", "clustering", "submodels", "regions"):
            fits[f"{step} seconds"] = exponent(
                n, [max(next(s["seconds"] for s in r["steps"] if s["step"] == step), 1e-4)
                    for r in sim])
        fits["peak memory above baseline"] = exponent(
            n, [max(r["peak_mb"] - r["baseline_mb"], 1.0) for r in sim])
    write_json({"load_average_1min": {"start": load_start, "end": load_end},
                "cpus": len(os.sched_getaffinity(0)), "cases": results, "exponents": fits},
               "scale")
    md = [f"Default fit per case, each in a fresh process; 1-minute load average "
          f"{load_start:.2f} at the start, {load_end:.2f} at the end, "
          f"{len(os.sched_getaffinity(0))} CPUs. Memory in MB (resident; the baseline is "
          "the process with the data loaded, before the fit).\n",
          pd.DataFrame(table).to_markdown(index=False, floatfmt=".3g"), "",
          "## Per step (peak: resident high-water mark during the step; estimate: the "
          "memory guard's, plus the baseline)\n",
          pd.DataFrame(steps).to_markdown(index=False, floatfmt=".3g"), "",
          "## Exponent b of time (memory) ∝ N^b on the simulated sizes\n",
          pd.Series(fits, name="b").to_markdown(floatfmt=".2f")]
    (RESULTS / "scale.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
