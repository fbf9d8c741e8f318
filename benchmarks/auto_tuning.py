"""The structure search's options on the simulated machines' tuning seeds.

``PWARX.auto(na=2, nb=2)`` as it is (the default), judged on five held-out blocks in turn
(``n_folds=5``), with ``refit=True`` and with ``oblique=False``, for each machine of
``MACHINES`` and tuning seeds 0–2 (the reporting seeds, from 1000, are not read), trained
and scored as ``benchmarks.machines`` does by default: 40 training experiments, the
free-run NRMSE on 10 held-out experiments of the same seed, 10-sample warm-up, averaged
over the outputs. Beside ``benchmarks.robot_auto_tuning`` (the robot's training
experiments), this is what decides the options' defaults. Writes
results/auto_tuning.{csv,md}.

Then one record per seed, as a user with one short experiment has (the cascaded tanks'
record is 1,024 samples): single records of 1,000 and 2,000 samples, tuning seeds 0–5,
scored on 10 held-out experiments of the seed, ``PWARX.auto(na=2, nb=2)`` judged on one
held-out block (``n_folds=1``) and as it is (``n_folds="auto"``: five blocks of the
1,000-sample record, three of the 2,000-sample one), beside the best linear ARX of
``benchmarks.machines`` (orders ≤ 6 with a constant, chosen on the record's last quarter).
Writes results/auto_tuning_one_record.{csv,md}: every seed, and the medians with the
seeds where the search loses to the linear model.

Usage: python -m benchmarks.auto_tuning [--one-record-only]
"""

import argparse
import itertools

import pandas as pd

from benchmarks._common import RESULTS, write_table
from benchmarks.machines import N_SAMPLES, N_TEST, N_TRAIN, best_linear, fitted, free_run
from pwa_pipeline import PWARX
from pwa_pipeline.datasets.machines import MACHINES, make_machine

SEEDS = range(3)
#: The search's options tried, by name.
VARIANTS = {"default": {}, "n_folds=5": {"n_folds": 5}, "refit=True": {"refit": True},
            "oblique=False": {"oblique": False}}
#: One record per seed: its lengths, the seeds, and the search's options tried.
ONE_RECORD_SAMPLES = (1000, 2000)
ONE_RECORD_SEEDS = range(6)
ONE_RECORD_VARIANTS = {"n_folds=1": {"n_folds": 1}, "default": {}}
LINEAR = "best linear ARX"


def one_record() -> None:
    """The single-record regime (module doc): every seed's free-run NRMSE, then the
    medians of each machine, length and method, and the seeds where a search variant
    scores worse than the best linear ARX."""
    rows = []
    for samples, machine, seed in itertools.product(ONE_RECORD_SAMPLES, MACHINES,
                                                    ONE_RECORD_SEEDS):
        data = make_machine(machine, 1, samples, seed, n_test=N_TEST)
        u, y = data.u_train, data.y_train

        def record(method, model, seconds, samples=samples, machine=machine, seed=seed,
                   data=data):
            rows.append({"samples": samples, "machine": machine, "seed": seed,
                         "method": method, "fit_seconds": seconds,
                         "free_run_nrmse": free_run(model, data.u_test, data.y_test)})
            print(rows[-1], flush=True)

        record(LINEAR, *best_linear(u, y)[:2])
        for name, options in ONE_RECORD_VARIANTS.items():
            record(f"PWARX.auto(2, 2) {name}",
                   *fitted(PWARX.auto(na=2, nb=2, **options), u, y))
    df = pd.DataFrame(rows)
    df.to_csv(RESULTS / "auto_tuning_one_record.csv", index=False)
    linear = df[df.method == LINEAR].set_index(["samples", "machine", "seed"]).free_run_nrmse
    summary = []
    for (samples, machine, method), g in df.groupby(["samples", "machine", "method"],
                                                    sort=False):
        worse = [int(r.seed) for r in g.itertuples()
                 if method != LINEAR and not r.free_run_nrmse <= linear[samples, machine, r.seed]]
        summary.append({"samples": samples, "machine": machine, "method": method,
                        "median free-run NRMSE": g.free_run_nrmse.median(),
                        "worst": g.free_run_nrmse.max(),
                        "seeds worse than linear": ", ".join(map(str, worse)) or
                        ("—" if method == LINEAR else "none")})
    (RESULTS / "auto_tuning_one_record.md").write_text(
        pd.DataFrame(summary).to_markdown(index=False, floatfmt=".4g") + "\n")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--one-record-only", action="store_true",
                        help="run the single-record regime only")
    args = parser.parse_args(argv)
    one_record()
    if args.one_record_only:
        return
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
