"""Does the estimation record's held-out part rank EMPS' structures as the test record does?

Five scheduled structures of EMPS (velocity form, orders (1, 1), a constant; regions from
the sign of the velocity Δy1(k-1), thresholds of the velocity at ±0.06 mm a sample, or a
threshold of the position at 0.1112 m, the one the search proposes), each by least squares
and refined on the free-run error (``OutputErrorRefinement(max_iter=30, patience=5,
one_step_weight=0.001)``, the search's). Each is scored twice: fitted on the first four
fifths of the estimation record and simulated on its last fifth (the search's held-out
NRMSE, 10-sample warm-up), and fitted on the whole estimation record and simulated on the
test record (RMSE in mm of ``qm[20:]``, the benchmark's convention). The rank correlation
of the two columns says whether any choice made on the estimation record can find the
structure the test record prefers. The velocity thresholds ±0.06 mm a sample are the best
of 0.03, 0.06 and 0.1 on the test record: that row shows what the model class can reach,
not a result of a choice made on estimation data. Writes results/held_out_ranking.{csv,md}.

Usage: python -m benchmarks.held_out_ranking
"""

import numpy as np
import pandas as pd
from scipy.stats import spearmanr

from benchmarks._common import RESULTS, write_table
from pwa_pipeline import PWARX, evaluate
from pwa_pipeline.datasets import load_dataset
from pwa_pipeline.pwa.output_error.estimator import OutputErrorRefinement
from pwa_pipeline.pwa.scheduling import SignScheduling
from pwa_pipeline.scoring.conventions import single_run_scores

#: Share of the estimation record the held-out score is fitted on (the search's split).
FIT_SHARE = 0.8


def velocity_above(t: float) -> dict:
    """z = y1(k-1) − y1(k-2) − t: the velocity above t (m a sample)."""
    return {"y1(k-1)": 1.0, "y1(k-2)": -1.0, "1": -t}


def position_above(t: float) -> dict:
    """z = y1(k-1) − t: the position above t (m)."""
    return {"y1(k-1)": 1.0, "1": -t}


#: (name, scheduling variables, what switches)
STRUCTURES = [
    ("offset on the velocity's sign", [velocity_above(0)], "offset"),
    ("offset on the velocity's sign and ±0.06 mm/sample",
     [velocity_above(0), velocity_above(6e-5), velocity_above(-6e-5)], "offset"),
    ("offset on the velocity's sign and the position", [velocity_above(0),
                                                         position_above(0.1112)], "offset"),
    ("all on the velocity's sign", [velocity_above(0)], "all"),
    ("all on the velocity's sign and the position", [velocity_above(0),
                                                      position_above(0.1112)], "all"),
]


def model(variables: list[dict], switch: str, refined: bool) -> PWARX:
    refinement = (OutputErrorRefinement(max_iter=30, patience=5, one_step_weight=0.001)
                  if refined else None)
    return PWARX(na=1, nb=1, affine=True, form="velocity",
                 scheduling=SignScheduling(variables=variables, switch=switch),
                 refinement=refinement)


def main() -> None:
    data = load_dataset("emps")
    u, y = data.u_train[0], data.y_train[0]
    cut = int(FIT_SHARE * len(y))
    rows = []
    for name, variables, switch in STRUCTURES:
        for refined in (False, True):
            held = model(variables, switch, refined).fit(u[:cut], y[:cut])
            whole = model(variables, switch, refined).fit(data.u_train, data.y_train)
            rows.append({
                "structure": name, "refined": refined,
                "held_out_nrmse": evaluate(held, u[cut:], y[cut:], warmup=10).mean("free_run"),
                "test_rmse_mm": float(np.mean(single_run_scores(whole, data.u_test,
                                                                data.y_test,
                                                                data.convention)))})
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    write_table(table, "held_out_ranking")
    rho = spearmanr(table["held_out_nrmse"], table["test_rmse_mm"]).statistic
    with open(RESULTS / "held_out_ranking.md", "a") as md:
        md.write(f"\nSpearman rank correlation of the held-out NRMSE and the test RMSE over "
                 f"the {len(table)} fits: {rho:.2f}.\n")
    print((RESULTS / "held_out_ranking.md").read_text())


if __name__ == "__main__":
    main()
