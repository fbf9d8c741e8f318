"""Is EMPS' estimation record one machine from start to end?

The record repeats one trajectory four times, so its two halves (two repeats each) ask the
same of the machine. The set ``output_error`` of data/hparams.toml (velocity form, orders
(2, 2), an offset per sign of the velocity, refined on the free-run error) is fitted on the
first half, on the second half and on the whole record, and each model is simulated on
each half (RMSE in mm after a 20-sample warm-up, the benchmark's convention). A
time-invariant machine would give each model about the same error on both halves; a
model scoring far better on the half it was fitted on than on the other, given the same
trajectory, says the machine (its friction, say, as it warms up) changed within the record.
Only the estimation record is read. Writes results/emps_halves.{csv,md}, the latter
with the largest gap between the halves' positions, sample by sample.

Usage: python -m benchmarks.emps_halves
"""

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, write_table
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import load_dataset
from pwa_pipeline.scoring.conventions import single_run_scores


def main() -> None:
    data = load_dataset("emps")
    u, y = data.u_train[0], data.y_train[0]
    half = len(y) // 2
    parts = {"first half": slice(0, half), "second half": slice(half, None),
             "whole record": slice(None)}
    model = HParamsFile().configuration("output_error", "emps").pwa
    rows = []
    for fitted_on, part in parts.items():
        fitted = clone(model).fit([u[part]], [y[part]])
        row = {"fitted on": fitted_on}
        for scored_on in ("first half", "second half"):
            s = parts[scored_on]
            rmse = single_run_scores(fitted, [u[s]], [y[s]], data.convention)
            row[f"RMSE mm on the {scored_on}"] = float(np.mean(rmse))
        rows.append(row)
        print(row, flush=True)
    write_table(pd.DataFrame(rows), "emps_halves")
    # the halves ask the same of the machine: their positions sample by sample
    gap = float(np.max(np.abs(y[:half, 0] - y[half:2 * half, 0]))) * 1000
    stroke = float(np.ptp(y[:, 0])) * 1000
    with open(RESULTS / "emps_halves.md", "a") as md:
        md.write(f"\nThe halves' positions differ by {gap:.1f} mm at most, sample by sample, "
                 f"over a {stroke:.0f} mm stroke.\n")


if __name__ == "__main__":
    main()
