"""The local least squares of step 3 on the robot: the compiled QR against LAPACK's, and how
well conditioned the local sets are.

On the KUKA training record (na = nb = 2, 39,856 local sets of n_ρ = 72 rows, d = 24,
m = 6), the default's local sets (``local_sets``, z-scored search) are solved by
``local_least_squares`` (Householder reflections compiled, ``pwa/_qr_kernels.py``) and by
the solve it replaced (LAPACK's QR, ``numpy.linalg.qr`` on blocks of 256 local sets, and a
back substitution over the stack), both on one thread, ``--repeats`` times alternated in
this process; reported:
the median CPU seconds of each, their ratio, and how far apart the results are (the largest
‖Δθ_k‖ / ‖θ_k‖ and relative difference of the residual variances; both QRs are backward
stable, so they differ by about the condition number times the rounding). Then the
condition numbers of the column-scaled local regressor matrices Φ_k (every 7th local set):
quantiles, which rule out the normal equations (their condition number is the square). The
1-minute load average is recorded at the start and the end.

Writes results/local_solve.json and .md. Usage::

    python -m benchmarks.local_solve [--repeats 5]
"""

import argparse
import os
import statistics
import time

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from benchmarks._common import RESULTS, write_json


def lapack_solve(phi: np.ndarray, target: np.ndarray, idx: np.ndarray, block: int = 256
                 ) -> tuple[np.ndarray, np.ndarray]:
    """θ_k and the residual variances of the local sets ``idx`` from LAPACK's QR of
    [Φ_k | Y_k] (column-scaled Φ_k, R₁₁ θ_k = R₁₂), every local set well posed: the solve before
    the compiled kernel."""
    from pwa_pipeline._arrays import column_rms

    d = phi.shape[1]
    scale = column_rms(phi)
    both = np.hstack([phi / scale, target])
    theta, resvar = [], []
    for start in range(0, len(idx), block):
        r = np.linalg.qr(np.take(both, idx[start:start + block], axis=0), mode="r")
        theta.append(_back_substitute(r[:, :d, :d], r[:, :d, d:]) / scale[:, None])
        resvar.append(np.einsum("kij,kij->kj", r[:, d:, d:], r[:, d:, d:])
                      / (idx.shape[1] - d))
    return np.concatenate(theta), np.concatenate(resvar)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    from pwa_pipeline import load_kuka
    from pwa_pipeline._arrays import column_rms
    from pwa_pipeline._validation import as_experiments
    from pwa_pipeline.pwa.steps import local_models
    from pwa_pipeline.regressors import build_regressors

    load_start = os.getloadavg()[0]
    robot = load_kuka()
    reg = build_regressors(as_experiments(robot.u_train, robot.y_train), 2, 2, False)
    phi, target = reg.phi, reg.target
    idx = local_models.local_sets(phi, 3 * phi.shape[1], standardize=True)
    solves = {"compiled QR (this code)":
              lambda: local_models.local_least_squares(phi, target, idx, workers=1)[:2],
              "LAPACK QR": lambda: lapack_solve(phi, target, idx)}
    cpu: dict[str, list[float]] = {name: [] for name in solves}
    results = {}
    with threadpool_limits(1):
        for _ in range(args.repeats):
            for name, solve in solves.items():
                c0 = time.process_time()
                results[name] = solve()
                cpu[name].append(time.process_time() - c0)
    (theta, resvar), (theta_ref, resvar_ref) = results.values()
    theta_diff = float(np.max(np.linalg.norm(theta - theta_ref, axis=(1, 2))
                              / np.linalg.norm(theta_ref, axis=(1, 2))))
    resvar_diff = float(np.max(np.abs(resvar - resvar_ref) / resvar_ref))
    sample = idx[::7]
    cond = np.linalg.cond(np.take(phi / column_rms(phi), sample, axis=0))
    quantiles = (0.0, 0.5, 0.9, 0.99, 1.0)
    load_end = os.getloadavg()[0]
    ref = statistics.median(cpu["LAPACK QR"])
    rows = [{"solve": name, "median CPU seconds": statistics.median(c),
             "ratio to LAPACK": statistics.median(c) / ref,
             "runs": ", ".join(f"{v:.2f}" for v in c)} for name, c in cpu.items()]
    conds = {f"q{q:g}": float(np.quantile(cond, q)) for q in quantiles}
    write_json({"repeats": args.repeats, "load_average_1min": {"start": load_start,
                                                               "end": load_end},
                "solves": rows, "max_relative_theta_difference": theta_diff,
                "max_relative_resvar_difference": resvar_diff,
                "condition_numbers": {"local_sets": len(sample), **conds}}, "local_solve")
    md = [f"Local least squares of the robot's default ({len(idx)} local sets of "
          f"{idx.shape[1]} rows, d = {phi.shape[1]}, m = {target.shape[1]}), one thread, "
          f"{args.repeats} runs per solve alternated in one process; 1-minute load "
          f"{load_start:.2f} at the start, {load_end:.2f} at the end.\n",
          pd.DataFrame(rows).to_markdown(index=False, floatfmt=".3g"), "",
          f"Largest ‖Δθ_k‖ / ‖θ_k‖ between the two: {theta_diff:.2g}; largest relative "
          f"difference of a residual variance: {resvar_diff:.2g}.", "",
          f"Condition numbers of the column-scaled Φ_k ({len(sample)} local sets, every "
          "7th), quantiles 0 / 0.5 / 0.9 / 0.99 / 1: "
          + " / ".join(f"{v:.3g}" for v in conds.values())]
    (RESULTS / "local_solve.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


def _back_substitute(upper: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve upper[k] · x[k] = rhs[k] for a stack of upper-triangular matrices (k, d, d), one
    row of all of them at a time with the stack as the last axis (the former library's)."""
    u = np.ascontiguousarray(upper.transpose(1, 2, 0))
    x = np.ascontiguousarray(rhs.transpose(1, 2, 0))
    for j in range(u.shape[0] - 1, -1, -1):
        x[j] /= u[j, j]
        if j:
            x[:j] -= u[:j, j, None, :] * x[j]
    return x.transpose(2, 0, 1)


if __name__ == "__main__":
    main()
