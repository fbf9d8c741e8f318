"""Compare PWA (paper setting and default), linear ARX and subspace models on held-out data.

Every method of the registry (pwa_pipeline.methods) is scored by the same protocol
(pwa_pipeline.scoring.evaluation): one-step-ahead and free-run, restarted at each held-out
experiment after a 10-sample warm-up. PWA runs with the sets ``paper``, ``default`` and
``output_error`` of data/hparams.toml, the baselines with ``default`` (and linear ARX also with
``output_error``), and the PWA model and linear ARX in the robot's structure (set ``robot``:
velocity form per joint, velocity-sign regions chosen per joint on held-out training
experiments, refined), and the structure search ``PWARX.auto`` (set ``auto``), on the data
sets that set has values for. Writes results/comparison.csv (dataset,
hparams, method, mode, output, nrmse, r2, rmse), results/comparison.md (the paper's Table 1
layout, one block per data set and mode), results/comparison_fit.csv (fit times, sub-model
counts, divergence flags) and results/conventions.md: every method's free run in each
convention of pwa_pipeline.scoring.conventions, with published figures beside them in the
convention they were published in.

Usage: python -m benchmarks.compare [--datasets hure_vasak kuka_robot] (the measured benchmarks:
benchmarks.measured)
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
from pwa_pipeline.scoring.conventions import CONVENTIONS, convention_scores

#: (set, method) pairs compared: the PWA model in both settings, the baselines once, the
#: PWA model and linear ARX with simulation-error refinement (set ``output_error``) and in
#: the robot's structure (set ``robot``, on the data sets it has values for), and the
#: structure search (set ``auto``; its linear twin is linear ARX of set ``default`` with a
#: constant, the search's own linear reference is in its report).
RUNS = ([("paper", "pwa")] + [("default", m) for m in METHODS]
        + [("output_error", "pwa"), ("output_error", "linear_arx"),
           ("robot", "pwa"), ("robot", "linear_arx"), ("auto", "pwa"), ("auto", "linear_arx")])
#: Published free-run scores on the KUKA test record, each in its own convention:
#: Fañanás-Anaya et al. (2025), Table VI — RMSE / range per joint, the test record run once.
PUBLISHED = [("MA-LSTM-MLP (Fañanás-Anaya et al. 2025)", "range_single_run", 0.125),
             ("LSTM-MLP (Fañanás-Anaya et al. 2025)", "range_single_run", 0.142),
             ("NARX-NN (Fañanás-Anaya et al. 2025)", "range_single_run", 0.146)]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["hure_vasak", "kuka_robot"],
                        choices=DATASETS)
    args = parser.parse_args(argv)
    rows, fits, conventions = [], [], []
    for name in args.datasets:
        try:
            data = load_dataset(name)
        except FileNotFoundError as exc:
            print(f"skipping {name}: {exc}")
            continue
        for hparams, method in RUNS:
            if not HParamsFile().covers(hparams, name):
                continue
            cfg = HParamsFile().configuration(hparams, name)
            with Timer() as t:
                model = clone(cfg.estimators[method]).fit(data.u_train, data.y_train)
            ev = evaluate(model, data.u_test, data.y_test, warmup=cfg.warmup,
                          output_names=data.y_names)
            rows.append(ev.table.assign(dataset=name, hparams=hparams, method=method))
            conventions.append({"dataset": name, "model": f"{method} ({hparams})",
                                **convention_scores(model, data.u_test, data.y_test)})
            fits.append({"dataset": name, "hparams": hparams, "method": method,
                         "fit_seconds": t.seconds,
                         "n_submodels": getattr(model, "n_submodels_", None),
                         "structures": ", ".join([o.structure for o in model.structure_fit_.outputs])
                         if hasattr(model, "structure_fit_") else None,
                         "free_run_diverged": ev.diverged()})
            print(f"{name:11s} {method:10s} ({hparams:7s}) fit {t.seconds:7.2f} s  one-step NRMSE "
                  f"{ev.mean('one_step'):.4g}  free-run NRMSE {ev.mean('free_run'):.4g}"
                  f"{'  (diverged)' if ev.diverged() else ''}", flush=True)
    table = pd.concat(rows, ignore_index=True)
    write_table(table[["dataset", "hparams", "method", "mode", "output", "nrmse", "r2", "rmse"]],
                "comparison")
    write_table(pd.DataFrame(fits), "comparison_fit")
    md = [f"## {ds} — {mode}\n\n" + table1(table, ds, mode, list(METHODS)).to_markdown(floatfmt=".4g") + "\n"
          for ds in table["dataset"].unique() for mode in ("one_step", "free_run")]
    (RESULTS / "comparison.md").write_text("\n".join(md))
    print("\n".join(md))
    write_conventions(pd.DataFrame(conventions))


def write_conventions(scores: pd.DataFrame) -> None:
    """results/conventions.md: the free run of every method in every convention, and the
    published KUKA figures in theirs (blank where a figure was not published that way)."""
    published = pd.DataFrame([{"dataset": "kuka_robot", "model": f"published: {label}",
                               key: value} for label, key, value in PUBLISHED])
    if "kuka_robot" in set(scores["dataset"]):
        scores = pd.concat([scores, published], ignore_index=True)
    notes = "\n".join(f"- `{c.name}`: normalised by {c.normalisation}, "
                      f"{'restarted at every experiment' if c.restart else 'one run'}, "
                      f"warm-up {c.warmup}" for c in CONVENTIONS.values())
    md = ["# Free-run scores in each convention\n", "Compare numbers within a column only.\n",
          notes + "\n"]
    md += [f"## {ds}\n\n" + g.drop(columns="dataset").set_index("model")
           .to_markdown(floatfmt=".4g") + "\n" for ds, g in scores.groupby("dataset", sort=False)]
    scores.to_csv(RESULTS / "conventions.csv", index=False)
    (RESULTS / "conventions.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
