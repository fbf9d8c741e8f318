"""The region SVMs of real fits solved both ways: two classes as Crammer and Singer's
multi-class problem and as the binary hinge-loss SVM with 2C (what ``SVMRegions`` does), and
at the tolerances 1e-4 (the default's) and 1e-3.

Each fit (``robot``, or a case of ``benchmarks.robustness`` at ``case:seed``) runs once with
the default in this process while every ``LinearSVC`` fit it makes is recorded (rows,
labels, weights, C, tolerance). Then every recorded fit is solved again, ``--repeats`` times
(the median): the two-class ones with scikit-learn's Crammer–Singer solver and with the
binary solver at the recorded tolerance, and every one (the multi-class fits with
Crammer–Singer) at tolerance 1e-4 and at 1e-3, whatever its recorded tolerance. Reported per
fit: the number of SVM fits, the seconds of each way, how many training rows the binary
solve labels as Crammer–Singer's does (the smallest share over the fit's SVMs), and the
largest relative difference of the hyperplanes; the 1-minute load before and after.

Writes results/region_svm.json and results/region_svm.md. Usage::

    python -m benchmarks.region_svm [--fits robot,paper-20dB:5001,paper-20dB:5002]
        [--repeats 3]
"""

import argparse
import os
import statistics
import time
import warnings

import numpy as np
import pandas as pd
from sklearn.exceptions import ConvergenceWarning
from sklearn.svm import LinearSVC

from benchmarks._common import RESULTS, write_json
from benchmarks._fits import default_fit


def recorded_svm_fits(fit: str) -> list[dict]:
    """Every ``LinearSVC`` fit of the default fit ``fit``: its rows, labels, weights, C, tol."""
    calls, original = [], LinearSVC.fit

    def recording(self, X, y, sample_weight=None):
        calls.append({"x": X.copy(), "y": y.copy(), "C": self.C, "tol": self.tol,
                      "w": None if sample_weight is None else sample_weight.copy(),
                      "binary": self.multi_class != "crammer_singer"})
        return original(self, X, y, sample_weight=sample_weight)

    est, u, y = default_fit(fit)
    LinearSVC.fit = recording
    try:
        est.fit(u, y)
    finally:
        LinearSVC.fit = original
    return calls


def solve(call: dict, way: str, tol: float) -> tuple[float, LinearSVC]:
    """Seconds and fitted SVM of one recorded fit, ``way`` "crammer_singer" or "binary" (C is
    the recorded problem's: halved back for a binary record)."""
    c = call["C"] / 2 if call["binary"] else call["C"]
    svm = (LinearSVC(C=2 * c, loss="hinge", max_iter=50000, random_state=0, tol=tol)
           if way == "binary" else
           LinearSVC(C=c, multi_class="crammer_singer", max_iter=50000, random_state=0,
                     tol=tol))
    t0 = time.perf_counter()
    svm.fit(call["x"], call["y"], sample_weight=call["w"])
    return time.perf_counter() - t0, svm


def hyperplane(svm: LinearSVC) -> np.ndarray:
    return np.r_[svm.coef_.ravel(), svm.intercept_]


def compare(fit: str, repeats: int) -> dict:
    calls = recorded_svm_fits(fit)
    two = [c for c in calls if len(np.unique(c["y"])) == 2]
    seconds = {key: 0.0 for key in ("crammer_singer", "binary", "tol 1e-4", "tol 1e-3")}
    agree, shift = [], []
    for call in calls:
        way = "binary" if len(np.unique(call["y"])) == 2 else "crammer_singer"
        for tol in (1e-4, 1e-3):
            seconds[f"tol {tol:.0e}".replace("e-0", "e-")] += statistics.median(
                solve(call, way, tol)[0] for _ in range(repeats))
    for call in two:
        solved = {}
        for way in ("crammer_singer", "binary"):
            runs = [solve(call, way, call["tol"]) for _ in range(repeats)]
            seconds[way] += statistics.median(t for t, _ in runs)
            solved[way] = runs[0][1]
        cs, binary = hyperplane(solved["crammer_singer"]), hyperplane(solved["binary"])
        agree.append(np.mean(solved["crammer_singer"].predict(call["x"])
                             == solved["binary"].predict(call["x"])))
        shift.append(np.linalg.norm(binary - cs) / np.linalg.norm(cs))
    return {"fit": fit, "svm fits": len(calls), "two-class fits": len(two),
            "two-class s, Crammer–Singer": seconds["crammer_singer"],
            "two-class s, binary": seconds["binary"],
            "smallest share of rows labelled alike": min(agree, default=np.nan),
            "largest relative hyperplane difference": max(shift, default=np.nan),
            "all fits s, tol 1e-4": seconds["tol 1e-4"],
            "all fits s, tol 1e-3": seconds["tol 1e-3"]}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fits", default="robot,paper-20dB:5001,paper-20dB:5002")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    load_start = os.getloadavg()[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        rows = [compare(fit, args.repeats) for fit in args.fits.split(",")]
    load_end = os.getloadavg()[0]
    table = pd.DataFrame(rows)
    write_json({"load average at start": load_start, "load average at end": load_end,
                "repeats": args.repeats, "fits": rows}, "region_svm")
    text = (f"The region SVMs of each default fit, recorded and solved again ({args.repeats} "
            f"repeats, medians, summed over the fit's SVMs); 1-minute load {load_start:.2f} "
            f"at the start, {load_end:.2f} at the end, 2 CPUs.\n\n"
            + table.to_markdown(index=False, floatfmt=".3g") + "\n")
    (RESULTS / "region_svm.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
