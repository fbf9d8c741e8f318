"""Held (piecewise-constant) inputs on the paper's section 5 system.

Each input value is held for 5–40 samples (uniform), as from a PLC, a PRBS or a step test;
N = 4000, 30 dB. For seeds 1000–1019 (never used while tuning the default), fits the default
PWARX and records: whether it raised, the number of sub-models, the share of degenerate local
sets, and the largest parameter error after matching (when 4 sub-models are found).

Writes results/held_inputs.md and .json. Usage: python -m benchmarks.held_inputs [--seeds 20]
"""

import argparse
import os

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, Timer, write_json
from pwa_pipeline import PWARX
from pwa_pipeline.datasets.simulated import HURE_VASAK_THETAS, add_output_noise, hure_vasak_mode
from pwa_pipeline.scoring.metrics import match_submodels

FIRST_SEED = 1000


def held_hure_vasak(n: int, seed: int, hold=(5, 40), snr_db: float = 30.0,
                    burn_in: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """The section 5 system with each input value held for ``hold`` samples (inclusive)."""
    rng = np.random.default_rng(seed)
    total = n + burn_in
    u = np.empty((total, 2))
    k = 0
    while k < total:
        h = int(rng.integers(hold[0], hold[1] + 1))
        u[k:k + h] = [rng.uniform(-4, 6), rng.uniform(-2, 4)]
        k += h
    y = np.zeros((total, 2))
    for k in range(1, total):
        y[k] = np.r_[y[k - 1], u[k - 1]] @ HURE_VASAK_THETAS[hure_vasak_mode(y[k - 1])]
    u, y = u[burn_in:], y[burn_in:]
    return u, y + add_output_noise(y, snr_db, rng)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    rows = []
    for seed in range(FIRST_SEED, FIRST_SEED + args.seeds):
        u, y = held_hure_vasak(4000, seed)
        try:
            with Timer() as t:
                m = PWARX(na=1, nb=1).fit(u, y)
        except ValueError as exc:
            rows.append({"seed": seed, "error": str(exc)})
            continue
        error = np.nanmax(match_submodels(m.thetas_, HURE_VASAK_THETAS)[1])
        rows.append({"seed": seed, "error": "", "n_submodels": m.n_submodels_,
                     "degenerate_share": m.steps_["local_models"].n_degenerate_
                     / len(m.steps_["submodels"].labels_),
                     "max_param_error": float(error) if m.n_submodels_ == 4 else np.nan,
                     "fit_seconds": t.seconds})
        print(rows[-1], flush=True)
    df = pd.DataFrame(rows)
    ok = df[df["error"] == ""]
    summary = {
        "load_average_at_start": load, "seeds": len(df), "raised": int((df["error"] != "").sum()),
        "exactly 4 sub-models": int((ok["n_submodels"] == 4).sum()),
        "median degenerate share": float(ok["degenerate_share"].median()),
        "median largest param error": float(ok["max_param_error"].median()),
        "worst largest param error": float(ok["max_param_error"].max())}
    write_json({"summary": summary, "rows": rows}, "held_inputs")
    (RESULTS / "held_inputs.md").write_text(
        pd.DataFrame([summary]).to_markdown(index=False, floatfmt=".3g") + "\n\n"
        + df.to_markdown(index=False, floatfmt=".3g") + "\n")
    print(summary)


if __name__ == "__main__":
    main()
