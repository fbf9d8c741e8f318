"""Single-output fit time: a 2-mode SISO PWARX record at N = 5k, 20k and 50k.

y(k) = 0.5·y(k−1) + u(k−1) where y(k−1) > 0, else −0.3·y(k−1) + 2·u(k−1) + 0.5, u white
uniform in [−1, 1], output noise σ = 0.01, affine regressors. On such records DBSCAN returns
tens of small clusters that step 5 merges. Times the default PWARX (median of ``--repeats``
runs) and, as the reference in the same run, the same fit with every row in the region SVM
(``regions__max_rows=None``, one run: it takes about a minute at 50k). Also records the number
of sub-models and the largest parameter error against the truth.

Writes results/siso.md and results/siso.json. Usage: python -m benchmarks.siso [--repeats 3]
"""

import argparse
import os
import statistics

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, Timer, write_json
from pwa_pipeline import PWARX
from pwa_pipeline.scoring.metrics import match_submodels

TRUTH = np.array([[[0.5], [1.0], [0.0]], [[-0.3], [2.0], [0.5]]])


def two_mode_siso(n: int, seed: int = 0, noise: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """The record of the module doc."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, (n, 1))
    y = np.zeros((n, 1))
    for k in range(1, n):
        mode = 0 if y[k - 1, 0] > 0 else 1
        y[k] = np.r_[y[k - 1], u[k - 1], 1.0] @ TRUTH[mode]
    return u, y + noise * rng.normal(size=y.shape)


def _fit(estimator: PWARX, u, y) -> dict:
    with Timer() as t:
        model = clone(estimator).fit(u, y)
    error = match_submodels(model.thetas_, TRUTH)[1]
    return {"seconds": t.seconds, "n_submodels": model.n_submodels_,
            "max_param_error": float(np.nanmax(error)), "step_seconds": model.timings_}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000, 50000])
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    default = PWARX.default(na=1, nb=1, affine=True)
    reference = clone(default).set_params(regions__max_rows=None)
    rows = []
    for n in args.sizes:
        u, y = two_mode_siso(n)
        runs = [_fit(default, u, y) for _ in range(args.repeats)]
        ref = _fit(reference, u, y)
        med = statistics.median(r["seconds"] for r in runs)
        rows.append({"N": n, "default median s": med, "runs s": [r["seconds"] for r in runs],
                     "sub-models": runs[0]["n_submodels"],
                     "largest param error": runs[0]["max_param_error"],
                     "step 5 s (median)": statistics.median(r["step_seconds"]["submodels"]
                                                            for r in runs),
                     "every-row SVM s": ref["seconds"], "every-row sub-models": ref["n_submodels"],
                     "ratio every-row / default": ref["seconds"] / med})
        print(rows[-1], flush=True)
    write_json({"load_average_at_start": load, "rows": rows}, "siso")
    table = pd.DataFrame(rows).drop(columns="runs s")
    (RESULTS / "siso.md").write_text(
        f"Load average at start: {load:.2f} (2 cores).\n\n"
        + table.to_markdown(index=False, floatfmt=".3g") + "\n")


if __name__ == "__main__":
    main()
