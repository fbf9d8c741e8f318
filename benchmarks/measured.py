"""Every method on every measured benchmark, scored in each benchmark's own convention.

The cascaded tanks (free-run RMSE in V of the test record from its 6th sample) and EMPS
(free-run RMSE in mm of ``qm[20:]`` of the test record), each fitted on its estimation record
alone (pwa_pipeline.datasets.measured), with this project's NRMSE (eq. 21, the same window)
beside the official figure. Methods: the sets of data/hparams.toml that have values for the
benchmark (``default``, ``output_error``) with their linear ARX twins, the structure search
``PWARX.auto(2, 2)`` (the set ``auto``), the best linear ARX of orders ≤ 4 with a constant
(orders chosen by the free run on the last fifth of the estimation record), the subspace
baseline, on the tanks a continuous PWA model with hinges of the level at the quartiles of
the estimation record (`quartile_hinges`), without and with the level's measured limit
(``output_limits="measured"``: 10 V, where the record sits flat), on EMPS the data set's own physical model
(`emps_physical_model`), and the published figures in the same convention (PUBLISHED,
sources in docs/measured.md). Writes
results/measured.csv and results/measured.md (with the machine's load while it ran), and
results/measured_search.md (what the search chose on each and why, `write_searches`).

Usage: python -m benchmarks.measured [--datasets cascaded_tanks emps]
"""

import argparse
import itertools
from types import SimpleNamespace

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_table
from pwa_pipeline import PWARX, LinearARX, evaluate
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import MEASURED, Dataset, load_dataset
from pwa_pipeline.pwa.limits import bounds
from pwa_pipeline.pwa.output_error import OutputErrorRefinement
from pwa_pipeline.pwa.scheduling import SignScheduling
from pwa_pipeline.scoring.conventions import single_run_scores

#: (set, method) pairs run where the set has values for the benchmark.
RUNS = [("default", "pwa"), ("default", "linear_arx"), ("default", "subspace"),
        ("output_error", "pwa"), ("output_error", "linear_arx")]
#: Published free-run figures on each test record, with the convention each was published in
#: (docs/measured.md gives the sources). The tanks' published rows score all 1024 samples, the
#: state taken from the estimation record, ours from the 6th, the state set by the first 5
#: samples: close conventions, not the same one.
TANKS_PUBLISHED = "V, all 1024 samples, state from the estimation record"
PUBLISHED = {
    "cascaded_tanks": [("BLA (Relan et al. 2017)", 0.75, TANKS_PUBLISHED),
                       ("Volterra (Birpoutsoukis et al. 2018)", 0.54, TANKS_PUBLISHED),
                       ("NLSS2 (Relan et al. 2017)", 0.34, TANKS_PUBLISHED),
                       ("neural CT state space (Forgione, Piga 2021)", 0.33, TANKS_PUBLISHED),
                       ("grey box (Rogers et al. 2017)", 0.18, TANKS_PUBLISHED)],
    "emps": [("dynoNet (Forgione, Piga 2021)", 2.64, "mm, RMSE over the test record")],
}
#: The physical model of EMPS identified by its authors (Janot, Gautier, Brunot 2019, §3.4:
#: inverse model, IDIM-LS, symmetric friction): mass kg, viscous N·s/m, Coulomb N, offset N,
#: and the drive gain N/V of the data files.
EMPS_IDIM = {"mass": 95.11, "viscous": 203.5, "coulomb": 20.39, "offset": -3.16,
             "gain": 35.1507}
#: Orders tried for the best linear ARX.
LINEAR_ORDERS = range(1, 5)


def best_linear(data: Dataset) -> tuple[LinearARX, str]:
    """Linear ARX with a constant, orders ≤ 4 chosen by the free run on the last fifth of the
    estimation record (fitted on the rest), refitted on all of it."""
    u, y = data.u_train[0], data.y_train[0]
    cut = int(0.8 * len(y))
    scores = {}
    for na, nb in itertools.product(LINEAR_ORDERS, LINEAR_ORDERS):
        model = LinearARX(na=na, nb=nb, affine=True).fit(u[:cut], y[:cut])
        scores[na, nb] = float(np.mean(single_run_scores(model, u[cut:], y[cut:],
                                                         data.convention)))
    na, nb = min(scores, key=lambda k: scores[k] if np.isfinite(scores[k]) else np.inf)
    return LinearARX(na=na, nb=nb, affine=True).fit(u, y), f"({na}, {nb})"


def quartile_hinges(data: Dataset, limits: str | None = None) -> tuple[PWARX, str]:
    """PWARX(2, 2) with a constant, one linear model plus a hinge max(0, y1(k−1) − t) at
    each quartile t of the estimation record's output (``switch="continuous"``), refined
    on the free-run error as the tanks' set ``output_error``: slopes that bend with the
    level, as a square-root outflow does; ``limits`` its ``output_limits``."""
    knots = np.round(np.quantile(np.concatenate(data.y_train)[:, 0], [0.25, 0.5, 0.75]), 2)
    scheduling = SignScheduling(variables=[{"y1(k-1)": 1.0, "1": -t} for t in knots],
                                switch="continuous")
    model = PWARX(na=2, nb=2, affine=True, scheduling=scheduling, output_limits=limits,
                  refinement=OutputErrorRefinement(max_iter=40, patience=5))
    return model, ", ".join(f"{t:g}" for t in knots)


def emps_physical_model(u: np.ndarray, y_init: np.ndarray, Ts: float) -> np.ndarray:
    """Free run of EMPS' physical model M q̈ = g·u − F_v q̇ − F_c sign(q̇) − offset
    (`EMPS_IDIM`), explicit Euler at the record's sample time, position and velocity
    set by the measured positions ``y_init`` (the warm-up): the grey-box reference in the
    I/O benchmark's own convention. Returns the positions, shape (len(u), 1)."""
    p, w = EMPS_IDIM, len(y_init)
    q = np.empty(len(u))
    q[:w] = np.asarray(y_init, dtype=float).ravel()
    force = p["gain"] * np.asarray(u, dtype=float).ravel()
    v = (q[w - 1] - q[w - 2]) / Ts
    for k in range(w, len(q)):
        a = (force[k - 1] - p["viscous"] * v - p["coulomb"] * np.sign(v) - p["offset"]) / p["mass"]
        v += Ts * a
        q[k] = q[k - 1] + Ts * v
    return q[:, None]


def physical_row(data: Dataset) -> dict:
    """The row of `emps_physical_model` on the test record, scored by the benchmark's own
    `single_run_scores` as every model is (nothing fitted: no fit time)."""
    convention, w = data.convention, data.convention.warmup
    physical = SimpleNamespace(simulate=lambda u, y_init: emps_physical_model(
        u, y_init, data.sample_time))
    official = float(single_run_scores(physical, data.u_test, data.y_test, convention)[0])
    y = data.y_test[0].ravel()
    return {"benchmark": data.name, "model": "physical model, IDIM-LS (Janot et al. 2019), "
            "simulated here", "official": official,
            "unit": f"{convention.unit}, RMSE from sample {w + 1}",
            "project_nrmse": official / convention.scale / float(np.std(y[w:])),
            "fit_seconds": np.nan}


def score_row(name: str, label: str, model, data: Dataset, seconds: float,
              warmup: int) -> dict:
    convention = data.convention
    official = float(np.mean(single_run_scores(model, data.u_test, data.y_test, convention)))
    ev = evaluate(model, data.u_test, data.y_test, warmup=warmup, output_names=data.y_names)
    return {"benchmark": name, "model": label, "official": official,
            "unit": f"{convention.unit}, RMSE from sample {convention.warmup + 1}",
            "project_nrmse": ev.mean("free_run"), "fit_seconds": seconds}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=list(MEASURED), choices=list(MEASURED))
    args = parser.parse_args(argv)
    hparams, rows, load, searches = HParamsFile(), [], MachineLoad(), {}
    for name in args.datasets:
        data = load_dataset(name)
        warmup = data.convention.warmup
        for set_name, method in RUNS:
            if not hparams.covers(set_name, name):
                continue
            cfg = hparams.configuration(set_name, name)
            with Timer() as t:
                model = clone(cfg.estimators[method]).fit(data.u_train, data.y_train)
            label = f"{method} ({set_name})"
            rows.append(score_row(name, label, model, data, t.seconds, warmup))
            print(rows[-1], flush=True)
        with Timer() as t:  # on every benchmark, whether or not a set `auto` has values for it
            model = PWARX.auto(na=2, nb=2).fit(data.u_train, data.y_train)
        label = "PWARX.auto(2, 2)" + (" [linear kept]" if model.structure_search_.linear else "")
        rows.append(score_row(name, label, model, data, t.seconds, warmup))
        print(rows[-1], flush=True)
        searches[name] = model.structure_search_
        with Timer() as t:
            model, orders = best_linear(data)
        rows.append(score_row(name, f"best linear ARX {orders}", model, data, t.seconds, warmup))
        print(rows[-1], flush=True)
        for limits in ([None, "measured"] if name == "cascaded_tanks" else []):
            model, knots = quartile_hinges(data, limits)
            with Timer() as t:
                model.fit(data.u_train, data.y_train)
            limited = bounds(model.output_limits_, 0, "y1")
            rows.append(score_row(name, f"PWARX(2, 2) continuous, hinges at y1 = {knots}, "
                                  "refined" + (f", limited to {limited} (measured)"
                                               if limited else ""),
                                  model, data, t.seconds, warmup))
            print(rows[-1], flush=True)
        if name == "emps":
            rows.append(physical_row(data))
            print(rows[-1], flush=True)
        rows += [{"benchmark": name, "model": f"published: {who}", "official": value,
                  "unit": unit, "project_nrmse": np.nan, "fit_seconds": np.nan}
                 for who, value, unit in PUBLISHED[name]]
    table = pd.DataFrame(rows)
    write_table(table, "measured")
    with open(RESULTS / "measured.md", "a") as md:  # the fit times are wall-clock seconds
        md.write(f"\nMachine: {describe_load(load.summary())}.\n")
    print((RESULTS / "measured.md").read_text())
    write_searches(searches)


def write_searches(searches: dict) -> None:
    """``results/measured_search.md``: what ``PWARX.auto(2, 2)`` chose on each benchmark and
    why (its report's choice and the rows that decided, held-out figures of each fold)."""
    parts = []
    for name, report in searches.items():
        rows = report.summary()[["stage", "structure", "validation_nrmse", "outcome"]]
        parts.append(f"## {name}\n\n{report.choice}\n\n"
                     + rows.to_markdown(index=False, floatfmt=".4g"))
    (RESULTS / "measured_search.md").write_text("\n\n".join(parts) + "\n")


if __name__ == "__main__":
    main()
