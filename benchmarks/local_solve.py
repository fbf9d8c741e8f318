"""The local least squares of step 3 on the robot: CPU time by block size, and how well
conditioned the local sets are.

On the KUKA training record (na = nb = 2, 39,856 local sets of n_ρ = 72 rows, d = 24,
m = 6), the default's local sets (``local_sets``, z-scored search) are solved by
``local_least_squares`` on one thread with blocks of 256 and of 1,024 local sets,
``--repeats`` times alternated in this process; reported: the median CPU seconds of each and
whether the results are the same to the bit. Then the condition numbers of the
column-scaled local regressor matrices Φ_k (every 7th local set): quantiles, which rule out
the normal equations (their condition number is the square). The 1-minute load average is
recorded at the start and the end.

Writes results/local_solve.json and .md. Usage::

    python -m benchmarks.local_solve [--repeats 5]
"""

import argparse
import os
import statistics
import time

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, write_json

BLOCKS = (256, 1024)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    from pwa_pipeline import load_kuka
    from pwa_pipeline._arrays import column_rms
    from pwa_pipeline._validation import as_experiments
    from pwa_pipeline.pwa import local_models
    from pwa_pipeline.pwa.regressors import build_regressors

    load_start = os.getloadavg()[0]
    robot = load_kuka()
    reg = build_regressors(as_experiments(robot.u_train, robot.y_train), 2, 2, False)
    phi, target = reg.phi, reg.target
    idx = local_models.local_sets(phi, 3 * phi.shape[1], standardize=True)
    default_block = local_models._CHUNK
    cpu: dict[int, list[float]] = {b: [] for b in BLOCKS}
    results = {}
    try:
        for _ in range(args.repeats):
            for block in BLOCKS:
                local_models._CHUNK = block
                c0 = time.process_time()
                results[block] = local_models.local_least_squares(phi, target, idx, workers=1)
                cpu[block].append(time.process_time() - c0)
    finally:
        local_models._CHUNK = default_block
    same = all(np.array_equal(a, b) for a, b in zip(*results.values()))
    sample = idx[::7]
    cond = np.linalg.cond(np.take(phi / column_rms(phi), sample, axis=0))
    quantiles = (0.0, 0.5, 0.9, 0.99, 1.0)
    load_end = os.getloadavg()[0]
    rows = [{"block (local sets)": b, "median CPU seconds": statistics.median(cpu[b]),
             "runs": ", ".join(f"{c:.2f}" for c in cpu[b])} for b in BLOCKS]
    conds = {f"q{q:g}": float(np.quantile(cond, q)) for q in quantiles}
    write_json({"repeats": args.repeats, "load_average_1min": {"start": load_start,
                                                               "end": load_end},
                "default_block": default_block, "blocks": rows, "same_results": same,
                "condition_numbers": {"local_sets": len(sample), **conds}}, "local_solve")
    md = [f"Local least squares of the robot's default ({len(idx)} local sets of "
          f"{idx.shape[1]} rows, d = {phi.shape[1]}, m = {target.shape[1]}), one thread, "
          f"{args.repeats} runs per block size alternated in one process; 1-minute load "
          f"{load_start:.2f} at the start, {load_end:.2f} at the end.\n",
          pd.DataFrame(rows).to_markdown(index=False, floatfmt=".3g"), "",
          f"The same results to the bit for every block size: {same}.", "",
          f"Condition numbers of the column-scaled Φ_k ({len(sample)} local sets, every "
          "7th), quantiles 0 / 0.5 / 0.9 / 0.99 / 1: "
          + " / ".join(f"{v:.3g}" for v in conds.values())]
    (RESULTS / "local_solve.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
