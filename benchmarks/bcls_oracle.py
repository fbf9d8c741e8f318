"""Least squares against bias-compensated least squares on the true modes' rows, per case of
``benchmarks.robustness`` (what the default's final refit chooses between, without the
estimation of the modes).

For each case and seed, the training record of ``benchmarks.robustness`` is split by its true
modes, and the sub-models are fitted by least squares and by
:func:`~pwa_pipeline.pwa.steps.submodels.bias_compensated_refit` (one-hot weights); reported per case:
the median and worst largest absolute parameter error of each, and on how many seeds the
compensation was the smaller. ``--set tune`` (the default here) uses the tuning seeds 100…,
so that a decision taken from it is not taken on the evaluation seeds.

Writes results/bcls_oracle{suffix}.md and .csv. Usage::

    python -m benchmarks.bcls_oracle [--set tune|eval] [--seeds 30] [--jobs 2]
"""

import argparse
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS
from benchmarks.robustness import CASES, FIRST_SEED, paper_system, random_system


def one_seed(name: str, seed: int) -> dict:
    """The largest parameter error of least squares and of BCLS on the true modes' rows."""
    from pwa_pipeline.pwa.steps.submodels import bias_compensated_refit, output_lag_columns, refit
    from pwa_pipeline.regressors import build_regressors

    case = CASES[name]
    system = (paper_system() if case.system is None
              else random_system(seed, **case.system, hold=case.hold))
    train = system.record(case.n, seed, case.snr_db, case.hold)
    s = system.thetas.shape[0]
    reg = build_regressors([(train.u, train.y)], system.na, system.nb, False)
    modes = train.modes[max(system.na, system.nb):]
    lags = output_lag_columns(reg.n_outputs, system.na, reg.phi.shape[1])
    ls = refit(reg.phi, reg.target, modes, s)
    bc = bias_compensated_refit(reg.phi, reg.target, np.eye(s)[modes], lags)[0]
    return {"case": name, "seed": seed,
            "ls": float(np.abs(ls - system.thetas).max()),
            "bcls": float(np.abs(bc - system.thetas).max())}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", choices=tuple(FIRST_SEED), default="tune")
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--suffix", default="")
    args = parser.parse_args(argv)
    first = FIRST_SEED[args.set]
    jobs = [(c, s) for c in CASES for s in range(first, first + args.seeds)]
    load = os.getloadavg()[0]
    with ProcessPoolExecutor(args.jobs) as pool:
        df = pd.DataFrame(pool.map(one_seed, *zip(*jobs, strict=True)))
    table = df.groupby("case", sort=False).agg(
        median_ls=("ls", "median"), median_bcls=("bcls", "median"),
        worst_ls=("ls", "max"), worst_bcls=("bcls", "max")).reset_index()
    table["seeds BCLS smaller"] = df.assign(w=df.bcls < df.ls).groupby("case", sort=False)[
        "w"].sum().to_numpy()
    head = (f"Seed set `{args.set}` (seeds {first}–{first + args.seeds - 1}), largest absolute "
            f"parameter error on the true modes' rows; 1-minute load {load:.2f} at the start.")
    RESULTS.mkdir(parents=True, exist_ok=True)
    stem = f"bcls_oracle{args.suffix}"
    df.to_csv(RESULTS / f"{stem}.csv", index=False)
    (RESULTS / f"{stem}.md").write_text(
        head + "\n\n" + table.to_markdown(index=False, floatfmt=".4g") + "\n")
    print(head)
    print(table.to_markdown(index=False, floatfmt=".4g"))


if __name__ == "__main__":
    main()
