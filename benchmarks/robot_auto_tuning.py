"""The structure search's settings on the robot, chosen on training data only.

Each variant of ``PWARX.auto(na=2, nb=2)`` (and, for reference, the set ``robot`` of
data/hparams.toml) is fitted on the KUKA training experiments 0–58 and scored on 59–65 (the
free-run NRMSE of this project's protocol, 10-sample warm-up, averaged over the joints). The
test record is not read. Writes results/robot_auto_tuning.{csv,md}.

Usage: python -m benchmarks.robot_auto_tuning
"""

import pandas as pd
from sklearn.base import clone

from benchmarks._common import Timer, write_table
from pwa_pipeline import PWARX, evaluate
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import load_dataset

#: Experiments 0–58 fit, 59–65 score.
CUT = 59
VARIANTS = {
    "search default": {},
    "judged on five held-out blocks in turn (n_folds=5)": {"n_folds": 5},
    "refit on every training experiment (refit=True)": {"refit": True},
    "min_gain = 0.05": {"min_gain": 0.05},
    "one variable per output (max_variables = 1)": {"max_variables": 1},
    "no oblique boundaries (oblique=False)": {"oblique": False},
    "candidates fitted on at most 20,000 rows (max_rows=20000)": {"max_rows": 20000},
}


def main() -> None:
    data = load_dataset("kuka_robot")
    u, y = data.u_train, data.y_train
    models = {name: PWARX.auto(na=2, nb=2, **kw)
              for name, kw in VARIANTS.items()}
    models["set robot (hand-written structure)"] = clone(
        HParamsFile().configuration("robot", "kuka_robot").pwa)
    rows = []
    for name, model in models.items():
        with Timer() as t:
            model.fit(u[:CUT], y[:CUT])
        score = evaluate(model, u[CUT:], y[CUT:], warmup=10).mean("free_run")
        rows.append({"variant": name, "free_run_nrmse_59_65": score, "fit_seconds": t.seconds})
        print(rows[-1], flush=True)
    write_table(pd.DataFrame(rows), "robot_auto_tuning")


if __name__ == "__main__":
    main()
