"""Identification report and speed (issue: core library).

1. The paper's simulation example (section 5: N = 4000, SNR 30 dB, seed 0) fitted with the
   paper's setting and with the default: number of sub-models, noise share, largest
   parameter error per true mode (sub-models matched to modes by parameters).
2. The full KUKA training record (39,988 samples, na = nb = 2): fit time of the paper setting
   (n_rho = 61, eps = 8, MinPts = 22) and of the default with n_rho = 61, median of
   ``--repeats`` runs, with the time of each step; the subspace baseline's fit time and peak
   memory (tracemalloc, numpy allocations included), as configured in data/hparams.toml.

The paper's values come from data/hparams.toml (sets ``paper``).
Writes results/identify.json and results/identify.md.
Usage: python -m benchmarks.identify [--repeats 3]
"""

import argparse
import statistics
import tracemalloc

import numpy as np
import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, Timer, write_json
from pwa_pipeline import load_kuka, make_hure_vasak
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.scoring.metrics import match_submodels


def mode_errors(thetas: np.ndarray, true: np.ndarray) -> list[float | None]:
    """Largest absolute parameter error of each true mode (None: no sub-model matched)."""
    mode_of, error = match_submodels(thetas, true)
    out: list[float | None] = [None] * len(true)
    for mode, err in zip(mode_of, error, strict=True):
        if mode >= 0:
            out[mode] = float(err)
    return out


def simulation_report() -> list[dict]:
    data = make_hure_vasak(n_samples=4000, snr_db=30.0, seed=0)
    hp = HParamsFile()
    rows = []
    for name in ("paper", "default"):
        model = clone(hp.configuration(name, "hure_vasak").pwa).fit(data.u_train[0], data.y_train[0])
        errs = mode_errors(model.thetas_, data.truth.thetas)
        noise, eps = model.steps_["clustering"].noise_share_, model.steps_["clustering"].eps_
        rows.append({"setting": name, "n_submodels": model.n_submodels_,
                     "noise_share": noise, "eps": eps,
                     **{f"max_error_mode{i + 1}": e for i, e in enumerate(errs)}})
        print(f"simulation, {name:7s}: {model.n_submodels_} sub-models, noise share "
              f"{noise:.1%}, eps {eps:.4g}, largest error per mode {errs}")
        print(np.round(model.thetas_.transpose(0, 2, 1), 4))
    return rows


def kuka_speed(repeats: int) -> list[dict]:
    try:
        robot = load_kuka()
    except FileNotFoundError as exc:
        print(f"skipping the KUKA timing: {exc}")
        return []
    hp = HParamsFile()
    settings = {"paper": hp.configuration("paper", "kuka_robot").pwa,
                "default, n_rho=61": clone(hp.configuration("default", "kuka_robot").pwa)
                .set_params(local_models__n_rho=61)}
    rows = []
    for name, estimator in settings.items():
        times, steps = [], []
        for _ in range(repeats):
            with Timer() as t:
                model = clone(estimator).fit(robot.u_train, robot.y_train)
            times.append(t.seconds)
            steps.append(model.timings_)
        med = {k: statistics.median(s[k] for s in steps) for k in steps[0]}
        rows.append({"setting": name, "median_seconds": statistics.median(times),
                     "runs": times, "n_submodels": model.n_submodels_,
                     "noise_share": model.steps_["clustering"].noise_share_,
                     **{f"step_{k}": v for k, v in med.items()}})
        print(f"KUKA fit, {name}: median {statistics.median(times):.2f} s over {repeats} "
              f"({', '.join(f'{x:.2f}' for x in times)}); steps {med}")
    tracemalloc.start()
    with Timer() as t:
        ss = clone(hp.configuration("default", "kuka_robot").estimators["subspace"]).fit(
            robot.u_train, robot.y_train)
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    rows.append({"setting": f"subspace, order {ss.order_}, horizon {ss.horizon}",
                 "median_seconds": t.seconds,
                 "peak_memory_mb": peak, "max_abs_pole": float(np.abs(ss.poles_).max())})
    print(f"KUKA subspace fit: {t.seconds:.2f} s, peak traced memory {peak:.0f} MB")
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    sim = simulation_report()
    kuka = kuka_speed(args.repeats)
    write_json({"simulation": sim, "kuka": kuka}, "identify")
    md = ["## Simulation example (N = 4000, 30 dB, seed 0)\n",
          pd.DataFrame(sim).to_markdown(index=False, floatfmt=".4g"), ""]
    if kuka:
        md += ["## KUKA training record (39,988 samples)\n",
               pd.DataFrame(kuka).drop(columns="runs", errors="ignore")
               .to_markdown(index=False, floatfmt=".4g"), ""]
    (RESULTS / "identify.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
