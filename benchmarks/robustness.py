"""Robustness of the default PWARX on the cases real excitation brings.

Cases (N = 4000 and 30 dB unless named otherwise):

- ``paper-30dB``, ``paper-25dB``, ``paper-20dB``: the section 5 system
  (:func:`~pwa_pipeline.make_hure_vasak`) at three noise levels;
- ``paper-held``: the same system, each input value held 5–40 samples;
- ``random-held``: random systems (below), inputs held 5–40 samples;
- ``rare-mode``: random 3-mode systems in which one mode holds 4 % of the samples
  (3–5 % over a long record), N = 2000;
- ``outputs-3``: 3 outputs, 2 inputs, 3 modes;
- ``order-2``: na = nb = 2, 2 outputs, 2 inputs, 3 modes;
- ``modes-5``: 2 outputs, 2 inputs, 5 modes;
- ``siso``: 1 output, 1 input, 3 modes.

A random system (:func:`random_system`) has modes θ_i = θ_0 + δ_i (δ_i on half the entries,
up to ±0.3), each stable on its own (companion spectral radius ≤ 0.85), regions
λ(k) = argmax_i (w_i·z(k) + b_i) on the z-scored regressor z(k) (hyperplanes in φ, the
structure the region SVM estimates), every mode holding at least half its fair share
(the rare mode: 4 %), and a bounded, switching response. Each seed is a different system.

Seed sets: ``--set tune`` uses seeds 100…; ``--set eval`` (the default, the figures the
README quotes) seeds 5000…, never used while tuning. For random cases the seed draws the
system and its records; for the paper cases the records.

Per run: whether the fit raised; the number of sub-models (exact = the true number); the
largest absolute parameter error after pairing sub-models with the true modes
(:func:`~pwa_pipeline.scoring.metrics.match_submodels`; only when the count is exact), and
beside it that of least squares on the true modes' rows (the oracle: what the record allows
a least-squares fit that knows the modes, errors in the variables included) and of
bias-compensated least squares on them (:func:`~pwa_pipeline.pwa.steps.submodels.bias_compensated_refit`,
what the default's final refit aims at); how many of the default's EM refits the
compensation's guard left at least squares (``n_uncompensated_`` of
:class:`~pwa_pipeline.pwa.steps.boundaries.ResidualRegions`, summed over the seeds);
region accuracy on a fresh noise-free record (:func:`~pwa_pipeline.scoring.truth.ground_truth_scores`);
free-run NRMSE on a fresh noisy record of the PWARX, of linear ARX and of the true system
(true θ and true regions); fit seconds.

Writes results/robustness{suffix}.md, .json and .csv. Usage::

    python -m benchmarks.robustness [--seeds 20] [--cases paper-25dB,rare-mode]
        [--set eval|tune] [--jobs 2] [--suffix _main] [--params submodels__settle_tol=0.5]
        [--n 40000]

On long records (``--n 40000``) the default estimates the local models of 5,000 samples
(``LocalLeastSquares.max_sets``); the same run with ``--params local_models__max_sets=None``
estimates every one, and the two tables compare the subset with the full step.

``--seeds 3 --cases ...`` is the quick form; the full run (10 cases × 20 seeds) takes about
15 minutes with ``--jobs 2``. The reference (the landed code on the same seeds) runs this
script with ``PYTHONPATH`` pointing at that checkout (``--suffix _main``); a variant of this
checkout's default sets step parameters with ``--params`` (written beside the table). Fit
seconds are wall time, with the fit's CPU seconds and step 5's wall seconds beside them.
"""

import argparse
import ast
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, write_json
from pwa_pipeline import PWARX, LinearARX, evaluate
from pwa_pipeline.datasets.simulated import HURE_VASAK_THETAS, add_output_noise, hure_vasak_mode
from pwa_pipeline.pwa.arx import ARXModelBase
from pwa_pipeline.pwa.steps.submodels import refit
from pwa_pipeline.regressors import build_regressors
from pwa_pipeline.scoring.metrics import match_submodels
from pwa_pipeline.scoring.truth import ground_truth_scores

FIRST_SEED = {"tune": 100, "eval": 5000}


@dataclass(frozen=True)
class Record:
    """One simulated record with its ground truth."""

    u: np.ndarray
    y: np.ndarray
    y_clean: np.ndarray
    modes: np.ndarray


class System:
    """A PWARX system y(k) = θ_λᵀ φ(k), λ(k) = ``mode_of(φ(k))``, φ as in eq. (2)–(3)."""

    def __init__(self, thetas, mode_of, na, nb, n_inputs, u_range=(-1.0, 1.0)):
        self.thetas, self.mode_of = thetas, mode_of
        self.na, self.nb, self.n_inputs = na, nb, n_inputs
        self.n_outputs = thetas.shape[2]
        self.u_range = u_range

    def inputs(self, n: int, rng: np.random.Generator, hold=None) -> np.ndarray:
        """White uniform inputs in ``u_range`` (per column), or each value held ``hold``
        = (shortest, longest) samples."""
        lo, hi = (np.broadcast_to(np.asarray(b, float), (self.n_inputs,)) for b in self.u_range)
        if hold is None:
            return rng.uniform(lo, hi, (n, self.n_inputs))
        u, k = np.empty((n, self.n_inputs)), 0
        while k < n:
            h = int(rng.integers(hold[0], hold[1] + 1))
            u[k:k + h] = rng.uniform(lo, hi)
            k += h
        return u

    def simulate(self, u: np.ndarray, burn_in: int = 100) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free outputs and modes for inputs ``u`` (the first ``burn_in`` dropped)."""
        na, nb, m = self.na, self.nb, self.n_outputs
        n0 = max(na, nb)
        n = u.shape[0]
        y = np.zeros((n, m))
        modes = np.zeros(n, int)
        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(n0, n):
                phi = np.concatenate([y[k - na:k][::-1].T.ravel(), u[k - nb:k][::-1].T.ravel()])
                modes[k] = self.mode_of(phi[None])[0]
                y[k] = phi @ self.thetas[modes[k]]
                if not np.all(np.abs(y[k]) < 1e6):
                    y[k:] = np.inf
                    break
        return y[burn_in:], modes[burn_in:]

    def record(self, n: int, seed: int, snr_db: float | None, hold=None,
               burn_in: int = 100) -> Record:
        rng = np.random.default_rng(seed)
        u = self.inputs(n + burn_in, rng, hold)
        y, modes = self.simulate(u, burn_in)
        noise = np.zeros_like(y) if snr_db is None else add_output_noise(y, snr_db, rng)
        return Record(u[burn_in:], y + noise, y, modes)


class TrueModel(ARXModelBase):
    """The true system as a fitted ARX model, for the free-run reference."""

    def __init__(self, system: System | None = None):
        self.system = system

    @property
    def na(self):
        return self.system.na

    @property
    def nb(self):
        return self.system.nb

    affine = False
    form = "level"
    outputs = "joint"

    def fit(self):
        self.n_inputs_, self.n_outputs_ = self.system.n_inputs, self.system.n_outputs
        return self

    def _predict_phi(self, phi):
        return np.einsum("nd,ndm->nm", phi, self.system.thetas[self.system.mode_of(phi)])


def paper_system() -> System:
    """The section 5 system (eq. 11–13)."""
    return System(HURE_VASAK_THETAS, lambda phi: hure_vasak_mode(phi[:, :2]), 1, 1, 2,
                  u_range=([-4.0, -2.0], [6.0, 4.0]))


def _stable(theta: np.ndarray, m: int, na: int, limit: float) -> bool:
    """Whether the autoregressive part of θ (φ order of eq. 3) has companion spectral radius
    ≤ ``limit``."""
    if na == 0:
        return True
    comp = np.zeros((m * na, m * na))
    for j in range(na):  # A_j[p, q] = θ[q·na + j, p]
        comp[:m, j * m:(j + 1) * m] = theta[np.arange(m) * na + j, :].T
    comp[m:, :-m] = np.eye(m * (na - 1))
    return bool(np.max(np.abs(np.linalg.eigvals(comp))) <= limit)


def random_system(seed: int, m: int, r: int, s: int, na: int = 1, nb: int = 1,
                  rare_share: float | None = None, hold=None) -> System:
    """A random PWARX system of the module doc (rejection sampling from ``seed``); with
    ``rare_share`` the last mode's intercept is set so that it holds that share of a long
    white-input record; the shares are checked on inputs held as ``hold``
    (:meth:`System.inputs`)."""
    rng = np.random.default_rng(seed)
    d = m * na + r * nb
    while True:
        base = np.zeros((d, m))
        base[:m * na] = rng.uniform(-0.6, 0.6, (m * na, m)) / max(m * na, 1) ** 0.5
        base[m * na:] = rng.uniform(-1.5, 1.5, (r * nb, m))
        thetas = np.empty((s, d, m))
        for i in range(s):
            delta = rng.uniform(-0.3, 0.3, (d, m)) * (rng.random((d, m)) < 0.5)
            thetas[i] = base + delta
        if not all(_stable(t, m, na, 0.85) for t in thetas):
            continue
        gaps = [np.abs(thetas[i] - thetas[j]).max() for i in range(s) for j in range(i)]
        if min(gaps) < 0.15:
            continue
        # z-score φ on a pilot record under mode 0
        pilot = System(thetas[:1], lambda p: np.zeros(len(p), int), na, nb, r)
        u0 = pilot.inputs(3000, rng)
        y0, _ = pilot.simulate(u0)
        sys0 = System(thetas, None, na, nb, r)
        phi0 = _phi(u0[100:], y0, na, nb)
        mu, sd = phi0.mean(axis=0), phi0.std(axis=0)
        w = rng.normal(size=(s, d))
        b = rng.normal(scale=0.3, size=s)
        sys0.mode_of = _argmax_regions(w / sd, b - (w / sd) @ mu)
        if rare_share is not None:
            b = _set_share(sys0, w / sd, b - (w / sd) @ mu, rare_share, rng)
            if b is None:
                continue
            sys0.mode_of = _argmax_regions(w / sd, b)
        y, modes = sys0.simulate(sys0.inputs(8100, rng, hold))
        if not np.all(np.isfinite(y)) or np.abs(y).max() > 100 * max(np.abs(y0).max(), 1e-9):
            continue
        share = np.bincount(modes, minlength=s) / len(modes)
        low = 0.5 / s
        if rare_share is not None:
            if not (0.03 <= share[-1] <= 0.05 and share[:-1].min() >= low):
                continue
        elif share.min() < low:
            continue
        if np.mean(modes[1:] != modes[:-1]) < 0.05:  # regions must switch, not stick
            continue
        return sys0


def _phi(u, y, na, nb):
    n0 = max(na, nb)
    return np.array([np.concatenate([y[k - na:k][::-1].T.ravel(), u[k - nb:k][::-1].T.ravel()])
                     for k in range(n0, len(y))])


def _argmax_regions(w, b):
    return lambda phi: np.argmax(phi @ w.T + b, axis=1)


def _set_share(system, w, b, share, rng):
    """The intercepts with the last one moved (bisection) so that the last mode holds
    ``share`` of a long record, or None."""
    u = system.inputs(20000, rng)
    lo, hi = -20.0, 20.0
    for _ in range(30):
        mid = (lo + hi) / 2
        bb = b.copy()
        bb[-1] += mid
        system.mode_of = _argmax_regions(w, bb)
        _, modes = system.simulate(u)
        got = np.mean(modes == len(b) - 1)
        if abs(got - share) < 0.003:
            return bb
        lo, hi = (mid, hi) if got < share else (lo, mid)
    return None


@dataclass(frozen=True)
class Case:
    n: int = 4000
    snr_db: float = 30.0
    hold: tuple | None = None
    system: dict | None = None  # random_system(**system); None: the paper system


CASES = {
    "paper-30dB": Case(),
    "paper-25dB": Case(snr_db=25.0),
    "paper-20dB": Case(snr_db=20.0),
    "paper-held": Case(hold=(5, 40)),
    "random-held": Case(hold=(5, 40), system=dict(m=2, r=2, s=3)),
    "rare-mode": Case(n=2000, system=dict(m=2, r=2, s=3, rare_share=0.04)),
    "outputs-3": Case(system=dict(m=3, r=2, s=3)),
    "order-2": Case(system=dict(m=2, r=2, s=3, na=2, nb=2)),
    "modes-5": Case(system=dict(m=2, r=2, s=5)),
    "siso": Case(system=dict(m=1, r=1, s=3)),
}


def one_run(name: str, seed: int, params: dict | None = None, n: int | None = None) -> dict:
    """One fit of case ``name`` at ``seed`` and its scores; ``params`` (e.g.
    ``{"submodels__settle_tol": 0.5}``) set on :meth:`PWARX.default` when given; records of
    ``n`` samples instead of the case's own when given."""
    case = CASES[name] if n is None else replace(CASES[name], n=n)
    system = (paper_system() if case.system is None
              else random_system(seed, **case.system, hold=case.hold))
    train = system.record(case.n, seed, case.snr_db, case.hold)
    fresh = system.record(case.n, seed + 100_000, case.snr_db, case.hold)
    clean = system.record(case.n, seed + 200_000, None, case.hold)
    s = system.thetas.shape[0]
    row = {"case": name, "seed": seed, "true_modes": s,
           "smallest_mode_share": float(np.bincount(train.modes, minlength=s).min()
                                        / len(train.modes)), "error": ""}
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        model = (PWARX(na=system.na, nb=system.nb) if not params else
                 PWARX.default(system.na, system.nb).set_params(**params)).fit(train.u, train.y)
    except Exception as exc:  # noqa: BLE001 - a raised fit is a result here
        return {**row, "error": f"{type(exc).__name__}: {exc}"[:200]}
    row["fit_seconds"] = time.perf_counter() - t0
    row["fit_cpu_seconds"] = time.process_time() - cpu0
    row["submodels_seconds"] = model.timings_["submodels"]
    truth = ground_truth_scores(model, system.thetas, clean.u, clean.y_clean, clean.modes)
    error = np.nanmax(match_submodels(model.thetas_, system.thetas)[1])
    reg = build_regressors([(train.u, train.y)], system.na, system.nb, False)
    modes = train.modes[max(system.na, system.nb):]
    oracle = refit(reg.phi, reg.target, modes, s)
    # imported here: benchmarks.robustness_time imports this module's generators beside the
    # packages of commits that predate these functions
    from pwa_pipeline.pwa.steps.submodels import bias_compensated_refit, output_lag_columns

    lags = output_lag_columns(reg.n_outputs, system.na, reg.phi.shape[1])
    oracle_bc = bias_compensated_refit(reg.phi, reg.target, np.eye(s)[modes], lags)[0]
    linear = LinearARX(system.na, system.nb).fit(train.u, train.y)
    free = {label: evaluate(mdl, fresh.u, fresh.y, warmup=10).mean("free_run")
            for label, mdl in [("pwarx", model), ("linear_arx", linear),
                               ("true", TrueModel(system).fit())]}
    return {**row, "n_submodels": model.n_submodels_, "exact": model.n_submodels_ == s,
            "max_param_error": float(error) if model.n_submodels_ == s else np.nan,
            "oracle_param_error": float(np.nanmax(np.abs(oracle - system.thetas))),
            "oracle_bc_param_error": float(np.nanmax(np.abs(oracle_bc - system.thetas))),
            "n_uncompensated": getattr(model.regions_, "n_uncompensated_", np.nan),
            "n_split": getattr(model.steps_["submodels"], "n_split_", np.nan),
            "region_accuracy": truth["region_accuracy"],
            **{f"free_run_nrmse_{k}": v for k, v in free.items()}}


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    out = []
    for name, g in df.groupby("case", sort=False):
        ok = g[g["error"] == ""]
        out.append({
            "case": name, "seeds": len(g), "raised": int((g["error"] != "").sum()),
            "exact mode count": f"{int(ok['exact'].sum())}/{len(g)}",
            "median largest param error": ok["max_param_error"].median(),
            "worst largest param error": ok["max_param_error"].max(),
            "oracle LS error": ok["oracle_param_error"].median(),
            "oracle BCLS error": ok["oracle_bc_param_error"].median(),
            "uncompensated refits": int(ok["n_uncompensated"].sum()),
            "median region accuracy": ok["region_accuracy"].median(),
            "worst region accuracy": ok["region_accuracy"].min(),
            "median free-run NRMSE": ok["free_run_nrmse_pwarx"].median(),
            "linear ARX": ok["free_run_nrmse_linear_arx"].median(),
            "true system": ok["free_run_nrmse_true"].median(),
            "median fit s": ok["fit_seconds"].median(),
            "median fit CPU s": ok["fit_cpu_seconds"].median(),
            "median step 5 s": ok["submodels_seconds"].median()})
    return pd.DataFrame(out)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--cases", default=",".join(CASES),
                        help=f"comma-separated subset of {', '.join(CASES)}")
    parser.add_argument("--set", choices=list(FIRST_SEED), default="eval",
                        help="seed set: eval (never used while tuning) or tune")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes")
    parser.add_argument("--suffix", default="", help="appended to the result file names")
    parser.add_argument("--params", default="",
                        help="comma-separated name=value set on PWARX.default, e.g. "
                             "submodels__settle_tol=0.5 (a variant; default: none)")
    parser.add_argument("--n", type=int, default=None,
                        help="samples of every record (default: each case's own)")
    args = parser.parse_args(argv)
    names = args.cases.split(",")
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        parser.error(f"unknown case(s) {unknown}; the cases are {list(CASES)}")
    first = FIRST_SEED[args.set]
    params = {k: ast.literal_eval(v) for k, v in (p.split("=") for p in args.params.split(",") if p)}
    jobs = [(name, seed, params, args.n) for name in names
            for seed in range(first, first + args.seeds)]
    load, t0 = os.getloadavg()[0], time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one_run, *zip(*jobs), chunksize=1))
    df = pd.DataFrame(rows)
    summary = summarise(df)
    stem = f"robustness{args.suffix}"
    RESULTS.mkdir(parents=True, exist_ok=True)
    df.to_csv(RESULTS / f"{stem}.csv", index=False)
    meta = {"seed set": args.set, "first seed": first, "seeds": args.seeds,
            "load average at start": load, "wall seconds": time.perf_counter() - t0,
            "jobs": args.jobs, "params": params, "n": args.n}
    write_json({"meta": meta, "summary": summary.to_dict("records")}, stem)
    (RESULTS / f"{stem}.md").write_text(
        f"Seed set `{args.set}` (seeds {first}–{first + args.seeds - 1}), "
        f"{meta['wall seconds']:.0f} s wall with {args.jobs} job(s), load {load:.2f} at "
        f"start (shared machine)"
        + (f"; variant `{args.params}`" if params else "")
        + (f"; records of N = {args.n} samples" if args.n else "") + ".\n\n"
        + summary.to_markdown(index=False, floatfmt=".4g") + "\n")
    print(summary.to_markdown(index=False, floatfmt=".4g"))


if __name__ == "__main__":
    main()
