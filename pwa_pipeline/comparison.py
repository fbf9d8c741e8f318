"""Fitting the compared methods by name, and the paper's Table 1 layout of their scores."""

import pandas as pd

from .config import HParams

METHODS = ("pwa_paper", "pwa_default", "linear_arx", "subspace")


def fit_method(method: str, hp: HParams, u, y):
    """Fit ``method`` (one of :data:`METHODS`) with the set ``hp`` on (u, y).

    ``pwa_paper`` and ``pwa_default`` both use ``hp``'s PWARX values (the caller picks the
    set); ``linear_arx`` uses its orders; ``subspace`` its baseline values.
    """
    if method in ("pwa_paper", "pwa_default"):
        return hp.pwa_model().fit(u, y)
    if method == "linear_arx":
        return hp.linear_model().fit(u, y)
    if method == "subspace":
        return hp.subspace_model().fit(u, y)
    raise ValueError(f"unknown method {method!r}; known: {list(METHODS)}")


def table1(scores: pd.DataFrame, dataset: str, mode: str) -> pd.DataFrame:
    """NRMSE and R² (%) per output and method, like the paper's Table 1, for one mode.

    ``scores`` has columns dataset, method, mode, output, nrmse, r2 (fraction).
    """
    sel = scores[(scores["dataset"] == dataset) & (scores["mode"] == mode)]
    wide = sel.pivot_table(index="output", columns="method", values=["nrmse", "r2"], sort=False)
    wide["r2"] = wide["r2"] * 100
    wide.columns = [f"{m} {'NRMSE' if k == 'nrmse' else 'R² %'}" for k, m in wide.columns]
    order = [c for m in METHODS for c in wide.columns if c.startswith(m + " ")]
    return wide[order]


def mean_scores(table: pd.DataFrame) -> pd.DataFrame:
    """Output-averaged NRMSE and R² per method (rows) and mode (columns), diverged runs
    marked; ``table`` has columns method, mode, output, nrmse, r2 and diverged."""
    means = table[table["output"] == "mean"]
    wide = means.pivot_table(index="method", columns="mode", values=["nrmse", "r2"],
                             sort=False)
    wide.columns = [f"{'NRMSE' if k == 'nrmse' else 'R²'} {mode}" for k, mode in wide.columns]
    if "diverged" in means:
        wide["free-run diverged"] = means[means["mode"] == "free_run"].set_index(
            "method")["diverged"]
    return wide
