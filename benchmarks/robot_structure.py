"""The robot structure's orders, chosen on training data only.

For each (na, nb) the set ``robot`` of data/hparams.toml is fitted on the KUKA training
experiments; its structure and refinement are chosen on the held-out training experiments
(the last 10 %, 59–65), and the score reported here is the free-run error on those same
held-out experiments (NRMSE per joint, RMSE over the training σ, averaged). The test record
is not read. Writes results/robot_structure.{csv,md}.

Usage: python -m benchmarks.robot_structure [--orders 1,1 2,1 1,2]
"""

import argparse

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import Timer, write_table
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import load_dataset


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orders", nargs="+", default=["1,1", "2,1", "1,2"])
    args = parser.parse_args(argv)
    data = load_dataset("kuka_robot")
    base = HParamsFile().configuration("robot", "kuka_robot").pwa
    sigma = np.std(np.vstack(data.y_train), axis=0)
    rows = []
    for spec in args.orders:
        na, nb = (int(v) for v in spec.split(","))
        with Timer() as t:
            model = clone(base).set_params(na=na, nb=nb).fit(data.u_train, data.y_train)
        fit = model.structure_fit_
        chosen = np.array([fit.validation_cost[j][s]
                           for j, s in enumerate(model.structure_.structures)])
        rows.append({"na": na, "nb": nb, "held_out_nrmse": float(np.mean(np.sqrt(chosen) / sigma)),
                     "structures": ", ".join(model.structure_.structures),
                     "held_out_experiments": f"{fit.validation_experiments[0]}-"
                                             f"{fit.validation_experiments[-1]}",
                     "fit_seconds": t.seconds})
        print(rows[-1], flush=True)
    write_table(pd.DataFrame(rows), "robot_structure")


if __name__ == "__main__":
    main()
