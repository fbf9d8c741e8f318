"""What bounds step 6's region accuracy: the gate with the true sub-models and modes.

On the records of :mod:`benchmarks.robustness` (tuning seeds 100…), the gate of
:func:`~pwa_pipeline.pwa.steps.boundaries.refine_boundaries` is started from the SVM on the true
modes and given the true θ_i, so neither the sub-models nor the labels limit it; it is
fitted on the measured φ (ridge 1e-5, the old default, and 1e-7), on φ with its output lags
denoised once (:func:`~pwa_pipeline.pwa.steps.boundaries.denoised_regressors` with the true modes
and noise variances) and on the noise-free φ (the limit without errors in the variables).
Per case: median region accuracy on a fresh noise-free record, and beside it the default's.

Writes results/region_limits.md and .csv. Usage::

    python -m benchmarks.region_limits [--seeds 8] [--cases paper-30dB,modes-5] [--jobs 2]
"""

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, write_table
from benchmarks.robustness import CASES, FIRST_SEED, paper_system, random_system
from pwa_pipeline import PWARX
from pwa_pipeline.pwa.steps.boundaries import denoised_regressors, previous_rows, refine_boundaries
from pwa_pipeline.pwa.steps.regions import SVMRegions
from pwa_pipeline.pwa.steps.submodels import output_lag_columns
from pwa_pipeline.regressors import build_regressors
from pwa_pipeline.scoring.truth import ground_truth_scores


def one_run(name: str, seed: int) -> dict:
    case = CASES[name]
    system = (paper_system() if case.system is None
              else random_system(seed, **case.system, hold=case.hold))
    train = system.record(case.n, seed, case.snr_db, case.hold)
    clean = system.record(case.n, seed + 200_000, None, case.hold)
    na, nb, thetas = system.na, system.nb, system.thetas
    lag = max(na, nb)
    reg = build_regressors([(train.u, train.y)], na, nb, False)
    noise_free = build_regressors([(train.u, train.y_clean)], na, nb, False).phi
    fresh = build_regressors([(clean.u, clean.y_clean)], na, nb, False).phi
    modes = train.modes[lag:]
    svm = SVMRegions().fit(reg.phi, modes, len(thetas))
    sigma2 = (train.y - train.y_clean).var(axis=0)
    denoised = denoised_regressors(
        reg.phi, reg.target, thetas, np.eye(len(thetas))[modes], sigma2,
        output_lag_columns(reg.n_outputs, na, reg.phi.shape[1]), previous_rows(reg.experiment),
        reg.phi)

    def accuracy(gate_phi, ridge):
        coef, intercept, _ = refine_boundaries(reg.phi, reg.target, thetas, svm.coef_,
                                               svm.intercept_, ridge, gate_phi=gate_phi)
        return float(np.mean(np.argmax(fresh @ coef.T + intercept, axis=1)
                             == clean.modes[lag:]))

    model = PWARX(na=na, nb=nb).fit(train.u, train.y)
    return {"case": name, "seed": seed,
            "default": ground_truth_scores(model, thetas, clean.u, clean.y_clean,
                                           clean.modes)["region_accuracy"],
            "SVM, true modes": float(np.mean(svm.predict(fresh) == clean.modes[lag:])),
            "gate, measured φ, ridge 1e-5": accuracy(reg.phi, 1e-5),
            "gate, measured φ, ridge 1e-7": accuracy(reg.phi, 1e-7),
            "gate, denoised φ, ridge 1e-7": accuracy(denoised, 1e-7),
            "gate, noise-free φ, ridge 1e-7": accuracy(noise_free, 1e-7)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--cases", default="paper-30dB,paper-held,random-held,modes-5")
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args(argv)
    first = FIRST_SEED["tune"]
    jobs = [(c, s) for c in args.cases.split(",") for s in range(first, first + args.seeds)]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = pd.DataFrame(list(pool.map(one_run, *zip(*jobs), chunksize=1)))
    summary = rows.drop(columns="seed").groupby("case", sort=False).median().reset_index()
    write_table(rows, "region_limits")
    print(summary.to_markdown(index=False, floatfmt=".4f"))
    (RESULTS / "region_limits.md").write_text(
        f"Median region accuracy on a fresh noise-free record, tuning seeds {first}–"
        f"{first + args.seeds - 1}; the gates use the true θ_i and start from the SVM on the "
        f"true modes (per seed: region_limits.csv).\n\n"
        + summary.to_markdown(index=False, floatfmt=".4f") + "\n")


if __name__ == "__main__":
    main()
