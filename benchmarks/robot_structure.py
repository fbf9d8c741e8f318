"""The robot structure's orders and one-step weight, chosen on training data only.

The set ``robot`` of data/hparams.toml is fitted on the KUKA training experiments; its
structure and refinement are chosen on the held-out training experiments (the last 10 %,
59–65), fitted on the others (0–58), and the scores reported here are on those same held-out
experiments. The test record is not read.

- ``--orders``: for each (na, nb), the free-run error of the chosen structures (NRMSE per
  joint, RMSE over the training σ, averaged). Writes results/robot_structure.{csv,md}.
- ``--weights``: for each one-step weight w of the refinement (J_w of
  pwa_pipeline.pwa.output_error) and each of ``--orders`` (default: the set's), the PWA
  model's and its linear twin's held-out free-run and one-step NRMSE (this project's
  protocol, pwa_pipeline.scoring.evaluation), beside the one-step NRMSE of linear ARX (set
  ``default``) fitted on 0–58. The pair kept is the one with the lowest held-out free-run
  NRMSE of the PWA model among those whose held-out one-step NRMSE is no worse than that
  linear ARX's. Writes results/robot_one_step_weight.{csv,md}.

Usage: python -m benchmarks.robot_structure [--orders 1,1 2,1 1,2] [--weights 0 0.1 1]
"""

import argparse

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, Timer, write_table
from pwa_pipeline import evaluate
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import load_dataset


def orders(data, base, specs: list[str]) -> None:
    """results/robot_structure: the held-out free-run error of each (na, nb)."""
    sigma = np.std(np.vstack(data.y_train), axis=0)
    rows = []
    for spec in specs:
        na, nb = (int(v) for v in spec.split(","))
        with Timer() as t:
            model = clone(base).set_params(na=na, nb=nb).fit(data.u_train, data.y_train)
        fit = model.structure_fit_
        chosen = np.array([fit.validation_cost[j][s]
                           for j, s in enumerate([o.structure for o in model.structure_fit_.outputs])])
        rows.append({"na": na, "nb": nb, "held_out_nrmse": float(np.mean(np.sqrt(chosen) / sigma)),
                     "structures": ", ".join([o.structure for o in model.structure_fit_.outputs]),
                     "held_out_experiments": f"{fit.validation_experiments[0]}-"
                                             f"{fit.validation_experiments[-1]}",
                     "fit_seconds": t.seconds})
        print(rows[-1], flush=True)
    write_table(pd.DataFrame(rows), "robot_structure")


def weights(data, cfg, values: list[float], specs: list[str]) -> None:
    """results/robot_one_step_weight: held-out free-run and one-step NRMSE per order and
    weight."""
    reference = clone(HParamsFile().configuration("default", "kuka_robot")
                      .estimators["linear_arx"])
    rows = []
    for spec, w in ((spec, w) for spec in specs for w in values):
        na, nb = (int(v) for v in spec.split(","))
        row: dict = {"na": na, "nb": nb, "one_step_weight": w}
        for method in ("pwa", "linear_arx"):
            est = clone(cfg.estimators[method]).set_params(na=na, nb=nb)
            est.set_params(refinement=clone(est.refinement).set_params(one_step_weight=w))
            with Timer() as t:
                model = est.fit(data.u_train, data.y_train)
            held = model.structure_fit_.validation_experiments
            if method == "pwa":
                row["structures"] = ", ".join([o.structure for o in model.structure_fit_.outputs])
                row["held_out_experiments"] = f"{held[0]}-{held[-1]}"
                fit_part = [i for i in range(len(data.u_train)) if i not in held]
            ev = evaluate(model, [data.u_train[i] for i in held],
                          [data.y_train[i] for i in held], warmup=cfg.warmup)
            row[f"{method}_free_run"] = ev.mean("free_run")
            row[f"{method}_one_step"] = ev.mean("one_step")
            row[f"{method}_fit_seconds"] = t.seconds
        rows.append(row)
        print(row, flush=True)
    ref = reference.fit([data.u_train[i] for i in fit_part], [data.y_train[i] for i in fit_part])
    ref_one_step = evaluate(ref, [data.u_train[i] for i in held], [data.y_train[i] for i in held],
                            warmup=cfg.warmup).mean("one_step")
    table = pd.DataFrame(rows).assign(linear_arx_default_one_step=ref_one_step)
    ok = table[table["pwa_one_step"] <= ref_one_step]
    chosen = None if ok.empty else ok.loc[ok["pwa_free_run"].idxmin()]
    write_table(table, "robot_one_step_weight")
    note = (f"\nKept: (na, nb) = ({chosen['na']}, {chosen['nb']}), one_step_weight = "
            f"{chosen['one_step_weight']:g}: the lowest held-out free-run NRMSE of the PWA "
            f"model among the rows whose held-out one-step NRMSE is no worse than linear "
            f"ARX's, {ref_one_step:.4g}.\n" if chosen is not None else
            f"\nNo row gives a held-out one-step NRMSE no worse than linear ARX's "
            f"({ref_one_step:.4g}).\n")
    with open(RESULTS / "robot_one_step_weight.md", "a") as f:
        f.write(note)
    print(note)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orders", nargs="*", default=None)
    parser.add_argument("--weights", nargs="*", type=float, default=None)
    args = parser.parse_args(argv)
    data = load_dataset("kuka_robot")
    cfg = HParamsFile().configuration("robot", "kuka_robot")
    if args.weights is None:
        orders(data, cfg.pwa, args.orders or ["1,1", "2,1", "1,2"])
    else:
        weights(data, cfg, args.weights or [0.0, 0.001, 0.01, 0.1, 0.5],
                args.orders or [f"{cfg.pwa.na},{cfg.pwa.nb}"])


if __name__ == "__main__":
    main()
