"""Whether a change of ``benchmarks.robustness``'s medians exceeds the spread over seeds: two
runs on the same seeds compared per case and seed.

For each case and metric (largest parameter error on the seeds where both found the true
number of modes, region accuracy, free-run NRMSE), the change of the median (``--new``
minus ``--old``) with a 95 % bootstrap interval (the seeds resampled with replacement,
paired: one draw takes a seed's value in both runs), the median of the per-seed differences,
and on how many seeds the new run is better / worse. An interval that holds 0 is a change
within the seeds' variance.

Writes results/robustness_paired{suffix}.md and .csv. Usage::

    python -m benchmarks.robustness_paired [--old robustness_main] [--new robustness]
        [--cases outputs-3] [--suffix _main]
"""

import argparse

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS

#: Metric column of ``benchmarks.robustness``'s CSV → whether lower is better.
METRICS = {"max_param_error": True, "region_accuracy": False, "free_run_nrmse_pwarx": True}


def paired_change(old: np.ndarray, new: np.ndarray, n_boot: int = 10_000, seed: int = 0
                  ) -> tuple[float, float, float]:
    """median(new) − median(old) and its 95 % paired-bootstrap interval."""
    rng = np.random.default_rng(seed)
    draw = rng.integers(0, len(old), (n_boot, len(old)))
    boot = np.median(new[draw], axis=1) - np.median(old[draw], axis=1)
    low, high = np.quantile(boot, [0.025, 0.975])
    return float(np.median(new) - np.median(old)), float(low), float(high)


def compare(old: pd.DataFrame, new: pd.DataFrame, cases: list[str]) -> pd.DataFrame:
    """One row per case and metric of the module doc."""
    rows = []
    for case in cases:
        both = old[old["case"] == case].merge(new[new["case"] == case], on="seed",
                                              suffixes=("_old", "_new"))
        for metric, lower in METRICS.items():
            pair = both[[f"{metric}_old", f"{metric}_new"]].dropna().to_numpy()
            if len(pair) < 2:
                continue
            change, low, high = paired_change(pair[:, 0], pair[:, 1])
            diff = pair[:, 1] - pair[:, 0]
            rows.append({"case": case, "metric": metric, "seeds": len(pair),
                         "median old": np.median(pair[:, 0]), "median new": np.median(pair[:, 1]),
                         "change of median": change, "95 % CI low": low, "95 % CI high": high,
                         "median paired difference": float(np.median(diff)),
                         "seeds better": int(((diff < 0) if lower else (diff > 0)).sum()),
                         "seeds worse": int(((diff > 0) if lower else (diff < 0)).sum())})
    return pd.DataFrame(rows)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", default="robustness_main", help="result stem (the reference)")
    parser.add_argument("--new", default="robustness", help="result stem")
    parser.add_argument("--cases", default="", help="comma-separated; default: every case")
    parser.add_argument("--suffix", default="", help="appended to the result file names")
    args = parser.parse_args(argv)
    old, new = (pd.read_csv(RESULTS / f"{stem}.csv") for stem in (args.old, args.new))
    cases = args.cases.split(",") if args.cases else list(dict.fromkeys(new["case"]))
    table = compare(old, new, cases)
    stem = f"robustness_paired{args.suffix}"
    table.to_csv(RESULTS / f"{stem}.csv", index=False)
    text = (f"`{args.new}` against `{args.old}` on the same seeds: change of the median with "
            "a 95 % paired-bootstrap interval (10,000 draws of the seeds), the median of the "
            "per-seed differences, and the seeds on which the new run is better / worse.\n\n"
            + table.to_markdown(index=False, floatfmt=".4g") + "\n")
    (RESULTS / f"{stem}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
