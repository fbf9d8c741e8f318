"""Baselines on the simulated machines (``pwa_pipeline.datasets.machines``): the figures a
structure search must beat.

For each machine of ``MACHINES`` and each of ``--seeds`` reporting seeds from
``--first-seed`` (default 1000: seeds 0–999 are for tuning and never reported), train on the
seed's ``--train`` training experiments and score the free run on ``--test`` held-out
experiments of the same seed (an independent random stream), 10-sample warm-up, NRMSE
averaged over outputs (``pwa_pipeline.evaluate``):

- ``PWARX.auto(2, 2)``: the structure search (``pwa_pipeline.pwa.search.search``), with
  its own held-out training experiments; the structure it chose is in the JSON;
- ``default``: the library default ``PWARX(na=2, nb=2)``;
- ``best linear ARX``: least-squares ``LinearARX(na, nb, affine=True)`` with the orders
  1 ≤ na, nb ≤ 6 of smallest free-run NRMSE on the last quarter of the *training*
  experiments (fitted on the other three quarters), then refitted on all of them;
- ``subspace``: ``SubspaceSS(horizon=10, refit="simulation")`` with the state dimension in
  {2, 4, 6, 8, 12} chosen the same way.

A free run whose NRMSE exceeds 10 (``evaluate``'s divergence threshold) counts as diverged.

Writes results/machines.json (every seed) and results/machines.md (medians over seeds,
with fit seconds of the final fit), or results/<name>.{json,md}. Usage:
python -m benchmarks.machines [--seeds 3] [--first-seed 1000] [--train 40] [--test 10]
[--samples 600] [--name machines]. One record of 1,000 samples per seed (the cascaded
tanks' length): --train 1 --samples 1000 --name machines_one_record.
"""

import argparse
import itertools

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_json
from pwa_pipeline import PWARX, LinearARX, SubspaceSS, evaluate
from pwa_pipeline.datasets.machines import MACHINES, REPORTING_FIRST_SEED, make_machine

WARMUP = 10
DIVERGENCE = 10.0
ORDERS = range(1, 7)
STATES = (2, 4, 6, 8, 12)
SUBSPACE = {"horizon": 10, "refit": "simulation"}
#: Training and held-out experiments per seed, and samples per experiment (the defaults).
N_TRAIN, N_TEST, N_SAMPLES = 40, 10, 600
#: `PWARX.auto`'s target: a free run at most this share of the best linear ARX's.
TARGET = 0.6


def free_run(model, u, y) -> float:
    """Free-run NRMSE averaged over outputs (inf when a run diverges to non-finite values)."""
    try:
        score = evaluate(model, u, y, warmup=WARMUP).mean("free_run")
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        return float("inf")
    return float(score) if np.isfinite(score) else float("inf")


def chosen(build, candidates, u, y) -> tuple[object, float]:
    """The candidate whose model, fitted on the first three quarters of the training
    experiments (of the samples, for a single record), has the smallest free-run NRMSE on
    the last quarter; with that score."""
    if len(u) == 1:
        cut = len(y[0]) - len(y[0]) // 4
        fit, held = ([u[0][:cut]], [y[0][:cut]]), ([u[0][cut:]], [y[0][cut:]])
    else:
        cut = len(u) - max(1, len(u) // 4)
        fit, held = (u[:cut], y[:cut]), (u[cut:], y[cut:])
    scores = {}
    for c in candidates:
        try:
            scores[c] = free_run(build(c).fit(*fit), *held)
        except (ValueError, np.linalg.LinAlgError):
            scores[c] = float("inf")
    best = min(scores, key=scores.get)
    return best, scores[best]


def fitted(model, u, y) -> tuple[object, float]:
    with Timer() as t:
        model.fit(u, y)
    return model, t.seconds


def best_linear(u, y) -> tuple[LinearARX, float, str, float]:
    """The best linear ARX with a constant, orders 1 ≤ na, nb ≤ 6 chosen by `chosen`,
    refitted on all the training data: (model, fit seconds, orders, held-out score)."""
    (na, nb), val = chosen(lambda o: LinearARX(na=o[0], nb=o[1], affine=True),
                           list(itertools.product(ORDERS, ORDERS)), u, y)
    model, seconds = fitted(LinearARX(na=na, nb=nb, affine=True), u, y)
    return model, seconds, f"({na}, {nb})", val


def one_seed(machine: str, seed: int, n_train: int, n_test: int, n_samples: int) -> list[dict]:
    data = make_machine(machine, n_train, n_samples, seed, n_test=n_test)
    u, y = data.u_train, data.y_train
    rows = []

    def record(method, model, seconds, **extra):
        rows.append({"machine": machine, "seed": seed, "method": method,
                     "free_run_nrmse": free_run(model, data.u_test, data.y_test), "fit_seconds": seconds,
                     **extra})

    auto, seconds = fitted(PWARX.auto(na=2, nb=2), u, y)
    record("PWARX.auto(2, 2)", auto, seconds, orders="searched, ≤ (2, 2)",
           structure=auto.structure_search_.choice,
           linear_fallback=auto.structure_search_.linear)
    record("default PWARX(2, 2)", *fitted(PWARX(na=2, nb=2), u, y))
    model, seconds, orders, val = best_linear(u, y)
    record("best linear ARX", model, seconds, orders=orders, validation_nrmse=val)
    order, val = chosen(lambda n: SubspaceSS(order=n, warmup=WARMUP, **SUBSPACE), STATES, u, y)
    record("subspace", *fitted(SubspaceSS(order=order, warmup=WARMUP, **SUBSPACE), u, y),
           orders=f"n = {order}", validation_nrmse=val)
    return rows


def diverged(x):
    return ~(x <= DIVERGENCE)


def shown(x: float) -> str:
    """A score as the table shows it: 4 digits, or "diverged"."""
    return "diverged" if diverged(pd.Series([x])).iloc[0] else f"{x:.4g}"


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    out = []
    for (machine, method), g in df.groupby(["machine", "method"], sort=False):
        orders = g["orders"].dropna() if "orders" in g else pd.Series(dtype=object)
        out.append({"machine": machine, "method": method, "seeds": len(g),
                    "diverged": f"{int(diverged(g.free_run_nrmse).sum())}/{len(g)}",
                    "median free-run NRMSE": shown(g.free_run_nrmse.median()),
                    "worst free-run NRMSE": shown(g.free_run_nrmse.max()),
                    "chosen orders": ", ".join(dict.fromkeys(orders)) if len(orders)
                    else "(2, 2)",
                    "median fit s": g.fit_seconds.median()})
    return pd.DataFrame(out)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=REPORTING_FIRST_SEED,
                        help="first seed (default: %(default)s; 0-999 are tuning seeds)")
    parser.add_argument("--train", type=int, default=N_TRAIN, help="training experiments")
    parser.add_argument("--test", type=int, default=N_TEST, help="held-out experiments")
    parser.add_argument("--samples", type=int, default=N_SAMPLES, help="samples per experiment")
    parser.add_argument("--name", default="machines",
                        help="results file stem (default: %(default)s)")
    args = parser.parse_args(argv)
    if args.first_seed < REPORTING_FIRST_SEED:
        print(f"warning: seeds below {REPORTING_FIRST_SEED} are tuning seeds, not for reporting")
    load = MachineLoad()
    rows = []
    with Timer() as total:
        for machine in MACHINES:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                rows += one_seed(machine, seed, args.train, args.test, args.samples)
                print(f"{machine}, seed {seed}: done", flush=True)
    df = pd.DataFrame(rows)
    summary = summarise(df)
    linear = summary[summary.method == "best linear ARX"].set_index("machine")
    auto = summary[summary.method == "PWARX.auto(2, 2)"].set_index("machine")
    target = {m: TARGET * float(linear.loc[m, "median free-run NRMSE"]) for m in linear.index}
    table = summary.to_markdown(index=False, floatfmt=".4g")
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    targets = "\n".join(
        f"- {m}: {TARGET} × {linear.loc[m, 'median free-run NRMSE']} = {t:.4g}; "
        f"`PWARX.auto` {auto.loc[m, 'median free-run NRMSE']} "
        f"({'met' if float(auto.loc[m, 'median free-run NRMSE']) <= t else 'not met'})"
        for m, t in target.items())
    (RESULTS / f"{args.name}.md").write_text(
        f"Free-run NRMSE (mean over outputs, 10-sample warm-up) on {args.test} held-out "
        f"experiments of {args.samples} samples, models trained on {args.train} training "
        f"experiments; medians over reporting seeds {seeds}. Orders of the linear ARX (with "
        "a constant) and state dimensions of the subspace model chosen on the last quarter "
        "of the training experiments.\n\n" + table + "\n\n"
        f"Target for `PWARX.auto`: free run ≤ {TARGET} × the best linear ARX:\n\n"
        + targets + f"\n\nTotal {total.seconds:.0f} s; {describe_load(load.summary())}.\n")
    write_json({"seeds": seeds, "n_train": args.train, "n_test": args.test,
                "n_samples": args.samples, "total_seconds": total.seconds,
                "load": load.summary(), "auto_target": target,
                "summary": summary.to_dict(orient="records"),
                "runs": df.replace({np.inf: None}).to_dict(orient="records")}, args.name)
    print(table)
    print(targets)
    print(f"total {total.seconds:.0f} s")


if __name__ == "__main__":
    main()
