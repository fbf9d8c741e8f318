"""The structure search's options on the simulated machines' tuning seeds.

``PWARX.auto(na=2, nb=2)`` as it is (the default), judged on five held-out blocks in turn
(``n_folds=5``), with ``refit=True`` and with ``oblique=False``, for each machine of
``MACHINES`` and tuning seeds 0–2 (the reporting seeds, from 1000, are not read), trained
and scored as ``benchmarks.machines`` does by default: 40 training experiments, the
free-run NRMSE on 10 held-out experiments of the same seed, 10-sample warm-up, averaged
over the outputs. Beside ``benchmarks.robot_auto_tuning`` (the robot's training
experiments), this is what decides the options' defaults. Writes
results/auto_tuning.{csv,md}.

Usage: python -m benchmarks.auto_tuning
"""

import pandas as pd

from benchmarks._common import write_table
from benchmarks.machines import N_SAMPLES, N_TEST, N_TRAIN, fitted, free_run
from pwa_pipeline import PWARX
from pwa_pipeline.datasets.machines import MACHINES, make_machine

SEEDS = range(3)
#: The search's options tried, by name.
VARIANTS = {"default": {}, "n_folds=5": {"n_folds": 5}, "refit=True": {"refit": True},
            "oblique=False": {"oblique": False}}


def main() -> None:
    rows = []
    for machine in MACHINES:
        for seed in SEEDS:
            data = make_machine(machine, N_TRAIN, N_SAMPLES, seed, n_test=N_TEST)
            for name, options in VARIANTS.items():
                model, seconds = fitted(PWARX.auto(na=2, nb=2, **options), data.u_train,
                                        data.y_train)
                rows.append({"machine": machine, "seed": seed, "search": name,
                             "free_run_nrmse": free_run(model, data.u_test, data.y_test),
                             "fit_seconds": seconds})
                print(rows[-1], flush=True)
    write_table(pd.DataFrame(rows), "auto_tuning")


if __name__ == "__main__":
    main()
