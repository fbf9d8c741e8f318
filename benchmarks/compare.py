"""Compare PWA (paper setting and default), linear ARX and subspace models on held-out data.

Every method of the registry (pwa_pipeline.methods) is scored by the same protocol
(pwa_pipeline.scoring.evaluation): one-step-ahead and free-run, restarted at each held-out
experiment after a 10-sample warm-up. PWA runs with the sets ``paper`` and ``default`` of
data/hparams.toml, the baselines with ``default``. Writes results/comparison.csv (dataset,
hparams, method, mode, output, nrmse, r2, rmse), results/comparison.md (the paper's Table 1
layout, one block per data set and mode) and results/comparison_fit.csv (fit times, sub-model
counts, divergence flags).

Usage: python -m benchmarks.compare [--datasets hure_vasak kuka_robot]
"""

import argparse

import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, Timer, write_table
from pwa_pipeline import evaluate
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import DATASETS, load_dataset
from pwa_pipeline.methods import METHODS
from pwa_pipeline.scoring.comparison import table1

#: (set, method) pairs compared: the PWA model in both settings, the baselines once.
RUNS = [("paper", "pwa")] + [("default", m) for m in METHODS]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=list(DATASETS), choices=DATASETS)
    args = parser.parse_args(argv)
    rows, fits = [], []
    for name in args.datasets:
        try:
            data = load_dataset(name)
        except FileNotFoundError as exc:
            print(f"skipping {name}: {exc}")
            continue
        for hparams, method in RUNS:
            cfg = HParamsFile().configuration(hparams, name)
            with Timer() as t:
                model = clone(cfg.estimators[method]).fit(data.u_train, data.y_train)
            ev = evaluate(model, data.u_test, data.y_test, warmup=cfg.warmup,
                          output_names=data.y_names)
            rows.append(ev.table.assign(dataset=name, hparams=hparams, method=method))
            fits.append({"dataset": name, "hparams": hparams, "method": method,
                         "fit_seconds": t.seconds,
                         "n_submodels": getattr(model, "n_submodels_", None),
                         "free_run_diverged": ev.diverged()})
            print(f"{name:11s} {method:10s} ({hparams:7s}) fit {t.seconds:7.2f} s  one-step NRMSE "
                  f"{ev.mean('one_step'):.4g}  free-run NRMSE {ev.mean('free_run'):.4g}"
                  f"{'  (diverged)' if ev.diverged() else ''}", flush=True)
    table = pd.concat(rows, ignore_index=True)
    write_table(table[["dataset", "hparams", "method", "mode", "output", "nrmse", "r2", "rmse"]],
                "comparison")
    write_table(pd.DataFrame(fits), "comparison_fit")
    md = [f"## {ds} — {mode}\n\n" + table1(table, ds, mode).to_markdown(floatfmt=".4g") + "\n"
          for ds in table["dataset"].unique() for mode in ("one_step", "free_run")]
    (RESULTS / "comparison.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
